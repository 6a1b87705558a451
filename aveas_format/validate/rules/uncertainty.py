"""Uncertainty: missing uncertainty for measured data and implausible standard deviations.

Negative or infinite ``_std``, correlations outside [-1, 1], probabilities outside [0, 1] and PMFs
that do not sum to 1 violate the declared ranges of those columns and are reported by the generic
rules ``structure.value_range`` and ``structure.pmf``.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, rule
from aveas_format.validate.views import StatesView, ints, num

#: docs/format.md §2: measured data SHOULD carry _std for x, y, heading, vx, vy (and length/width, see
#: participants.size_std_missing)
STATE_STDS = ("x_std", "y_std", "heading_std", "vx_std", "vy_std")


def seg_median(seg: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(segments, median of ``values`` per segment) for values grouped by ``seg`` (NaN dropped;
    the median of an even count is the mean of the two middle values).

    One sort of complex numbers (segment number + 1j value: NumPy sorts them by real, then
    imaginary part) orders the values within each segment: at 9M values 6x faster than
    ``np.lexsort((values, seg))``, whose indirect sorts dominated the uncertainty rules. Segments
    in runs (``seg`` non-decreasing: the states view's) are numbered from their run boundaries,
    others through ``np.unique``."""
    ok = ~np.isnan(values)
    seg, values = seg[ok], values[ok]
    n = len(seg)
    if not n:
        return np.zeros(0, np.int64), np.zeros(0)
    if bool((seg[1:] >= seg[:-1]).all()):
        cut = np.flatnonzero(seg[1:] != seg[:-1]) + 1
        segs = seg[np.r_[0, cut]]
        counts = np.diff(np.r_[0, cut, n])
        number = np.repeat(np.arange(len(segs), dtype=np.float64), counts)
    else:
        segs, inverse = np.unique(seg, return_inverse=True)
        counts = np.bincount(inverse, minlength=len(segs))
        number = inverse.astype(np.float64)  # exact: fewer than 2**53 segments
    keyed = np.empty(n, np.complex128)
    keyed.real = number
    keyed.imag = values
    keyed.sort()
    v = keyed.imag
    first = np.cumsum(counts) - counts
    return segs, 0.5 * (v[first + (counts - 1) // 2] + v[first + counts // 2])


@rule("uncertainty.std_missing", "warning", "Measured states without uncertainty",
      "states.parquet: row {row}: participant {participant_id} is measured but {column} is {state}"
      "{more}", scope="rows",
      enforces=("docs/format.md §2: measured data (provenance natural or staged) SHOULD carry _std for "
                "x, y, heading, vx, vy"))
def std_missing(ctx: Context) -> Iterator[Hits | Hit]:
    """Measured participants (provenance natural or staged) have states without ``x_std``,
    ``y_std``, ``heading_std``, ``vx_std`` or ``vy_std`` (the column is absent, or null for the
    participant's samples): docs/format.md §2 says measured data SHOULD carry them. One finding per column
    (absent) or per participant and column (nulls)."""
    sv = ctx.states_view
    if sv is None or not sv.measured.any():
        return
    for c in STATE_STDS:
        if not sv.present(c):
            if ctx.batch_index:
                continue  # reported with the first batch of a streamed table
            i = int(np.flatnonzero(sv.measured)[0])
            n = int(np.unique(sv.seg[sv.measured]).size)
            if ctx.file_rows:  # a batch: count the measured participants of the whole recording
                n = max(n, int(ctx.participants_view.measured.sum()))
            yield Hit(file="states.parquet", table="states", column=c, row=int(sv.row[i]),
                      participant_id=int(sv.pid[i]), state="absent",
                      more=f" (and {n - 1} more measured participants)" if n > 1 else "")
            continue
        v = sv.col(c)
        if v is None:
            continue
        miss = sv.measured & np.isnan(v)
        if miss.any():
            idx = np.flatnonzero(miss)
            first = idx[np.r_[0, np.flatnonzero(np.diff(sv.seg[idx])) + 1]]
            yield Hits(total=len(first), arrays={"row": sv.row[first],
                                                 "participant_id": sv.pid[first],
                                                 "time": sv.t[first]},
                       const={"file": "states.parquet", "table": "states", "column": c,
                              "state": "null", "more": ""})


@rule("uncertainty.class_pmf_missing", "warning", "Measured participant without class PMF",
      "participants.parquet: row {row}: participant {participant_id} is measured but class_pmf is "
      "{state}",
      enforces="docs/format.md §4: class_pmf SHOULD be given for measured data")
def class_pmf_missing(ctx: Context) -> Iterator[Hits]:
    """A measured participant has no ``class_pmf`` (column absent or null): docs/format.md §4 says
    class_pmf SHOULD be given for measured data (classification is uncertain)."""
    pv = ctx.participants_view
    t = pv.table
    if t is None or not pv.n or not pv.measured.any():
        return
    if "class_pmf" in t.column_names:
        isnull = np.asarray(t.column("class_pmf").is_null().to_numpy(zero_copy_only=False), bool)
        state = "null"
    else:
        isnull = np.ones(pv.n, bool)
        state = "absent"
    bad = pv.measured & isnull
    if bad.any():
        rows = np.flatnonzero(bad)
        yield Hits(total=len(rows), arrays={"row": rows, "participant_id": pv.pid[rows]},
                   const={"file": "participants.parquet", "table": "participants",
                          "column": "class_pmf", "state": state})


@rule("uncertainty.std_implausibly_large", "warning", "Standard deviation implausibly large",
      "{file}: row {row}: {column} = {value} exceeds the plausible {maximum}", scope="rows",
      enforces=quality("plausible_std"))
def std_implausibly_large(ctx: Context) -> Iterator[Hits]:
    """A ``_std`` value exceeds the plausible maximum of ``[uncertainty] std_max`` (e.g. x_std
    above 10 m, heading_std above 1 rad): usually a variance stored as a standard deviation, or a
    wrong unit. One finding per row and column."""
    maxima = ctx.config.uncertainty.std_max
    for name in ("states", "participants"):
        t = ctx.row_table(name)
        if t is None:
            continue
        pid = ints(t, "participant_id")
        for c, mx in maxima.items():
            v = num(t, c, name)
            if v is None:
                continue
            bad = v > mx
            if bad.any():
                rows = np.flatnonzero(bad)
                arrays = {"row": rows, "value": v[rows]}
                if pid is not None:
                    arrays["participant_id"] = pid[rows]
                yield Hits(total=len(rows), arrays=arrays,
                           const={"file": f"{name}.parquet", "table": name, "column": c,
                                  "maximum": mx})


def _jitter(sv: StatesView, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(segments, robust sample-to-sample noise of p per segment) from second differences of
    equally spaced samples at >= 10 Hz: sigma = sqrt(median(d2²) / 6 / 0.455) (white noise)."""
    if sv.n < 3:
        return np.zeros(0, np.int64), np.zeros(0)
    same2 = sv.same[1:] & sv.same[:-1]
    dt = np.diff(sv.t)
    even = np.abs(dt[1:] - dt[:-1]) < 1e-3 * np.maximum(dt[1:], 1e-9)
    ok = same2 & even & (dt[1:] <= 0.1)
    d2 = p[2:] - 2 * p[1:-1] + p[:-2]
    vals = np.where(ok, d2 ** 2, np.nan)
    segs, med = seg_median(sv.seg[1:-1], vals)
    # median of a chi-square(1) variable is 0.455 of its mean
    return segs, np.sqrt(med / 6.0 / 0.455)


@rule("uncertainty.std_implausibly_small", "warning", "Standard deviation implausibly small",
      "states.parquet: row {row}: participant {participant_id}: {column} = {value} {why}", scope="rows",
      enforces=quality("plausible_std"))
def std_implausibly_small(ctx: Context) -> Iterator[Hits]:
    """A measured participant claims more precision than its data has: a ``_std`` of exactly 0
    (0 means exact, i.e. simulation), or a stated x/y standard deviation that is smaller than the
    sample-to-sample jitter of its own positions divided by ``[uncertainty] jitter_factor`` (jitter
    from second differences at >= 10 Hz; jitter below ``jitter_floor_m`` is never reported). One
    finding per participant and column."""
    sv = ctx.states_view
    if sv is None or not sv.measured.any():
        return
    cfg = ctx.config.uncertainty
    base = {"file": "states.parquet", "table": "states"}
    for c in STATE_STDS:
        v = sv.col(c)
        if v is None:
            continue
        zero = sv.measured & (v == 0)
        if zero.any():
            idx = np.flatnonzero(zero)
            first = idx[np.r_[0, np.flatnonzero(np.diff(sv.seg[idx])) + 1]]
            yield Hits(total=len(first), arrays={"row": sv.row[first], "participant_id": sv.pid[first],
                                                 "time": sv.t[first], "value": v[first]},
                       const={**base, "column": c, "why": "for measured data (0 means exact)"})
    for c in ("x", "y"):
        p, s = sv.col(c), sv.col(c + "_std")
        if p is None or s is None:
            continue
        segs, jit = _jitter(sv, p)
        ssegs, stated = seg_median(sv.seg, np.where(s > 0, s, np.nan))
        common, a, b = np.intersect1d(segs, ssegs, return_indices=True)
        jit, stated = jit[a], stated[b]
        measured = sv.measured[sv.starts[common]]
        bad = measured & (jit > cfg.jitter_floor_m) & (stated * cfg.jitter_factor < jit)
        if bad.any():
            i = sv.starts[common[bad]]
            yield Hits(total=len(i), arrays={
                "row": sv.row[i], "participant_id": sv.pid[i], "value": np.round(stated[bad], 4),
                "why": [f"(median) while its positions jitter by {j:.3g} m" for j in jit[bad][:1000]]},
                const={**base, "column": c + "_std"})
