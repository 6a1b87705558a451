"""Time: the range of ``time``, its increase per participant, sample rates, gaps, interpolation.

Decreasing times are a sort-order problem (structure.sort_order) and repeated times a key problem
(structure.duplicate_key); ``time.not_increasing`` reports the increments too small to be real (float
noise of merged or re-timed sources).
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import shapely

from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, rule
from aveas_format.validate.views import ints, num


def _duration(ctx: Context) -> float | None:
    return float(ctx.meta.duration_s) if ctx.meta is not None else None


@rule("time.out_of_range", "error", "time outside [0, duration_s]",
      "{file}: row {row}: {column} = {value} s lies outside [0, duration_s = {duration}]",
      enforces="docs/format.md §3: every `time` lies in [0, duration_s]", scope="rows")
def out_of_range(ctx: Context) -> Iterator[Hits]:
    """A ``time`` (states, interior) or an interval bound (``time_start``/``time_end`` of
    unobserved, events, environment) lies before 0 or after recording.json ``duration_s``
    (tolerance ``[time] tolerance_s``)."""
    d = _duration(ctx)
    if d is None:
        return
    tol = ctx.config.time.tolerance_s
    for name, cols in (("states", ("time",)), ("interior", ("time",)),
                       ("unobserved", ("time_start", "time_end")),
                       ("events", ("time_start", "time_end")),
                       ("environment", ("time_start", "time_end"))):
        t = ctx.row_table(name)
        if t is None:
            continue
        pid = ints(t, "participant_id")
        for c in cols:
            v = num(t, c, name)
            if v is None:
                continue
            bad = (v < -tol) | (v > d + tol)
            if bad.any():
                rows = np.flatnonzero(bad)
                arrays = {"row": rows, "value": v[rows], "time": v[rows]}
                if pid is not None:
                    arrays["participant_id"] = pid[rows]
                yield Hits(total=len(rows), arrays=arrays,
                           const={"file": f"{name}.parquet", "table": name, "column": c,
                                  "duration": d})


@rule("time.not_increasing", "error", "time does not increase between samples",
      "states.parquet: row {row}: participant {participant_id}: time {time} s follows the previous "
      "sample after only {dt} s (below the resolution {resolution} s)",
      enforces="docs/format.md §5: (participant_id, time) unique; time strictly increasing per "
               "participant", scope="rows")
def not_increasing(ctx: Context) -> Iterator[Hits]:
    """Two consecutive samples of one participant are less than ``[time] resolution_s`` (1 µs)
    apart but not equal: float noise, not a new measurement. Equal times are
    structure.duplicate_key, decreasing ones structure.sort_order."""
    sv = ctx.states_view
    if sv is None or sv.n < 2:
        return
    res = ctx.config.time.resolution_s
    dt = np.diff(sv.t)
    bad = sv.same & (dt > 0) & (dt < res)
    if bad.any():
        i = np.flatnonzero(bad) + 1
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "dt": dt[i - 1]},
                   const={"file": "states.parquet", "table": "states", "column": "time",
                          "resolution": res})


@rule("time.nominal_rate_low", "warning", "Nominal sample rate below 10 Hz",
      "recording.json: nominal_rate_hz = {value} Hz is below {minimum} Hz",
      enforces=("docs/format.md §3: nominal_rate_hz SHOULD be above 10 Hz (the paper: several Hz, "
                "preferably more than 10 Hz)"))
def nominal_rate_low(ctx: Context) -> Iterator[Hit]:
    """recording.json ``nominal_rate_hz`` is below ``[time] min_rate_hz`` (10 Hz): the paper asks
    for several Hz, preferably more than 10 Hz."""
    if ctx.meta is None:
        return
    lo = ctx.config.time.min_rate_hz
    if ctx.meta.nominal_rate_hz < lo:
        yield Hit(file="recording.json", column="nominal_rate_hz", value=ctx.meta.nominal_rate_hz,
                  minimum=lo)


@rule("time.rate_below_nominal", "warning", "Participant sampled below the nominal rate",
      "states.parquet: row {row}: participant {participant_id} is sampled at {rate} Hz (median), "
      "below nominal_rate_hz = {nominal} Hz", scope="rows",
      enforces=quality("sampling"))
def rate_below_nominal(ctx: Context) -> Iterator[Hits]:
    """A participant's median sample rate is more than ``[time] rate_tolerance`` (10 %) below the
    recording's ``nominal_rate_hz``. One finding per participant, at its first row."""
    sv = ctx.states_view
    if sv is None or ctx.meta is None or sv.n < 2:
        return
    nominal = ctx.meta.nominal_rate_hz
    dt = np.diff(sv.t)
    seg = sv.seg[1:][sv.same]
    d = dt[sv.same]
    if not len(d):
        return
    # median step per participant: sort steps by (segment, dt) and pick the middle of each
    order = np.lexsort((d, seg))
    seg_s = seg[order]
    d_s = d[order]
    first = np.r_[0, np.flatnonzero(np.diff(seg_s)) + 1]
    counts = np.diff(np.r_[first, len(seg_s)])
    med = 0.5 * (d_s[first + (counts - 1) // 2] + d_s[first + counts // 2])
    rate = np.where(med > 0, 1.0 / np.where(med > 0, med, 1), np.inf)
    bad = rate < nominal * (1 - ctx.config.time.rate_tolerance)
    if bad.any():
        segs = seg_s[first][bad]
        i = sv.starts[segs]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "rate": np.round(rate[bad], 3)},
                   const={"file": "states.parquet", "table": "states", "nominal": nominal})


def _regions(ctx: Context):
    """(time_start, time_end, geometries) of unobserved.parquet, or None."""
    u = ctx.table("unobserved")
    if u is None or not u.num_rows or "geometry" not in u.column_names:
        return None
    ts = num(u, "time_start", "unobserved")
    te = num(u, "time_end", "unobserved")
    if ts is None or te is None:
        return None
    try:
        geoms = shapely.from_wkb(u.column("geometry").to_numpy(zero_copy_only=False), on_invalid="ignore")
    except Exception:  # noqa: BLE001 — reported by unobserved.invalid_geometry
        return None
    return ts, te, geoms


@rule("time.gap", "warning", "Gap in a trajectory",
      "states.parquet: row {row}: participant {participant_id}: no sample between {time_before} s "
      "and {time} s ({dt} s, nominal step {step} s) and no unobserved region explains it", scope="rows",
      enforces=quality("gaps"))
def gap(ctx: Context) -> Iterator[Hits]:
    """Two consecutive samples of a participant are more than ``[time] gap_factor`` nominal steps
    apart and the gap is not explained by an unobserved region (one whose interval overlaps the gap
    and whose polygon contains the position before or after it)."""
    sv = ctx.states_view
    if sv is None or ctx.meta is None or sv.n < 2:
        return
    step = 1.0 / ctx.meta.nominal_rate_hz
    dt = np.diff(sv.t)
    bad = sv.same & (dt > ctx.config.time.gap_factor * step)
    if not bad.any():
        return
    i = np.flatnonzero(bad)  # sample before the gap; i + 1 after
    reg = _regions(ctx)
    if reg is not None:
        x, y = sv.col("x"), sv.col("y")
        ts, te, geoms = reg
        explained = np.zeros(len(i), bool)
        if x is not None and y is not None:
            for k in range(len(ts)):
                g = geoms[k]
                if g is None:
                    continue
                hit = (ts[k] <= sv.t[i + 1]) & (te[k] >= sv.t[i])
                if not hit.any():
                    continue
                j = np.flatnonzero(hit & ~explained)
                inside = (shapely.contains_xy(g, x[i[j]], y[i[j]])
                          | shapely.contains_xy(g, x[i[j] + 1], y[i[j] + 1]))
                explained[j[inside]] = True
        i = i[~explained]
    if len(i):
        yield Hits(total=len(i), arrays={"row": sv.row[i + 1], "participant_id": sv.pid[i + 1],
                                         "time": sv.t[i + 1], "time_before": sv.t[i],
                                         "dt": np.round(dt[i], 6)},
                   const={"file": "states.parquet", "table": "states", "step": round(step, 6)})


@rule("time.interpolated_share", "info", "Mostly interpolated participant",
      "states.parquet: row {row}: participant {participant_id}: {share}% of its samples are "
      "interpolated (filled in, not measured)", scope="rows")
def interpolated_share(ctx: Context) -> Iterator[Hits]:
    """More than ``[time] interpolated_share`` (50 %) of a participant's samples have
    ``interpolated`` = true: most of its trajectory is filled in, not measured."""
    sv = ctx.states_view
    if sv is None or not sv.present("interpolated"):
        return
    v = sv.col("interpolated")
    if v is None or not sv.n:
        return
    flag = np.nan_to_num(v) > 0
    share = np.add.reduceat(flag.astype(np.float64), sv.starts) / (sv.ends - sv.starts)
    bad = share > ctx.config.time.interpolated_share
    if bad.any():
        i = sv.starts[bad]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "share": np.round(100 * share[bad], 1)},
                   const={"file": "states.parquet", "table": "states", "column": "interpolated"})


@rule("time.interval_order", "error", "Interval ends before it starts",
      "{file}: row {row}: time_end {time_end} s is before time_start {time} s",
      enforces="docs/format.md §6-8: validity intervals have time_start <= time_end")
def interval_order(ctx: Context) -> Iterator[Hits]:
    """An event or environment row has ``time_end`` < ``time_start`` (unobserved regions:
    unobserved.time_order)."""
    for name in ("events", "environment"):
        t = ctx.table(name)
        ts, te = num(t, "time_start", name), num(t, "time_end", name)
        if ts is None or te is None:
            continue
        bad = te < ts
        if bad.any():
            rows = np.flatnonzero(bad)
            yield Hits(total=len(rows), arrays={"row": rows, "time": ts[rows], "time_end": te[rows]},
                       const={"file": f"{name}.parquet", "table": name, "column": "time_end"})
