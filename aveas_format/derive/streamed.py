"""Every criticality measure of a recording too large for memory, by time window
(docs/derive.md "Large recordings").

:func:`derive_by_windows` reads ``states.parquet`` once, row group by row group, into chunks of
whole tracks (temporary Arrow files). A worker process per chunk derives its ``kinematics`` (the
smoother sees each track whole) and splits the chunk by time window: the whole tracks of the
participants present in window K (states and kinematics) go to window K's temporary files. Then a
worker per window ``[t0, t1)`` derives ``conflicts`` on those whole tracks (a crossing needs
both paths up to the crossing point), ``interactions`` on the states of the window's own time
steps (:func:`aveas_format.derive.interactions.compute` with ``core``: a time step's pairs need
that step only; the later states of its participants tell only their routes, the lanes a leader
search follows past a chain's end) and the window's criticality summary, and writes the rows of
its core as parts of the derived tables: ``OUT/kinematics/part-J.parquet``,
``OUT/interactions/part-K.parquet``, ``OUT/conflicts/...`` (a Parquet dataset each). The windows'
summaries merge into ``OUT/criticality_summary.parquet`` (sums of TET, TIT, observed time and
counts; minima with their std, time and pair; CPI weighted by time). A window's work grows with
its own time steps (its share of the whole tracks is only read and searched for routes and
crossings); memory is bounded by one row group in the parent and one chunk or window per
worker, whatever the recording's length.

Differences from deriving the whole recording at once (tests/derive/test_streamed.py): none in
the rows of kinematics, interactions and conflicts (the 2D Monte Carlo draws are keyed by pair
and time); a pair's TTC episode cut by a window boundary is two episodes for the TET/TIT Monte
Carlo std (their variances add).
"""

from __future__ import annotations

import functools
import shutil
import tempfile
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.feather as feather
import pyarrow.parquet as pq

#: the derivations run per window (events: their episodes per window, joined across the
#: windows' boundaries when assembled)
WINDOW_DERIVATIONS = ("kinematics", "interactions", "conflicts", "events")
#: every derived table :func:`write_by_windows` writes
WINDOW_TABLES = (*WINDOW_DERIVATIONS, "criticality_summary")
#: the default window (s): its participants' whole tracks and its derived rows are what one
#: worker holds (docs/performance.md "Derivations and criticality")
DEFAULT_WINDOW_S = 60.0
#: rows per row group of a window's part files
PART_ROW_GROUP = 16_384
#: rows per sorted piece when a derived table is assembled from the windows' parts
ASSEMBLE_ROWS = 250_000


def _peak_kb() -> int | None:
    try:
        for ln in Path("/proc/self/status").read_text().splitlines():
            if ln.startswith("VmHWM"):
                return int(ln.split()[1])
    except OSError:
        return None
    return None


def _row_groups(source: Path, name: str | None = None) -> Iterator[pa.Table]:
    """The row groups of ``states.parquet`` of the recording ``source`` (``name`` None) or of the
    Parquet files ``source/part-*.parquet`` in order."""
    if name is not None:
        from aveas_format.io.container import Container

        with Container(source) as c:
            pf = pq.ParquetFile(c.input_file(name))
            for g in range(pf.metadata.num_row_groups):
                yield pf.read_row_group(g)
        return
    for f in sorted(source.glob("part-*.parquet")):
        pf = pq.ParquetFile(f)
        for g in range(pf.metadata.num_row_groups):
            yield pf.read_row_group(g)


def _track_chunks(path: Path, tmp: Path, rows: int) -> list[int]:
    """Write the states in chunks of whole tracks (about ``rows`` rows each, cut between
    participants) to ``tmp/c-J.arrow``; return the chunk numbers."""
    from aveas_format.errors import FormatError

    out: list[int] = []
    held: list[pa.Table] = []
    n_held, last = 0, None

    def flush(tables: list[pa.Table]) -> None:
        j = len(out)
        feather.write_feather(pa.concat_tables(tables), tmp / f"c-{j}.arrow", compression="lz4")
        out.append(j)

    for rg in _row_groups(path, "states.parquet"):
        pid = rg.column("participant_id").to_numpy()
        if len(pid) and (np.any(np.diff(pid) < 0) or (last is not None and pid[0] < last)):
            raise FormatError("states.parquet is not sorted by participant_id (FORMAT.md): "
                              "sort it (aveas-format repair) before deriving by windows")
        if not len(pid):
            continue
        last = int(pid[-1])
        held.append(rg)
        n_held += len(pid)
        if n_held >= rows:
            whole = pa.concat_tables(held)
            p = whole.column("participant_id").to_numpy()
            cut = int(np.searchsorted(p, p[-1], side="left"))  # the last track may go on
            if cut > 0:
                flush([whole.slice(0, cut)])
                held, n_held = [whole.slice(cut)], len(p) - cut
    if n_held:
        flush(held)
    return out


def _write_part(table: pa.Table, path: Path) -> None:
    """A window's or chunk's part of a derived table: small row groups (read back by their
    participant ids' statistics, the only ones written), dictionaries for the string columns
    only (as the format's writer: trying them on every float column doubles the time to write
    and read)."""
    pq.write_table(table, path, row_group_size=PART_ROW_GROUP, write_statistics=["participant_id"],
                   use_dictionary=[f.name for f in table.schema if pa.types.is_string(f.type)
                                   or pa.types.is_dictionary(f.type)] or False)


def _chunk_task(j: int, *, path: str, tmp: str, out: str, window_s: float,
                params: dict[str, Any]) -> dict[str, Any]:
    """``derived/kinematics`` of chunk ``j`` of whole tracks, written as ``out/kinematics/part-J``;
    and the chunk's states and kinematics split by time window: the whole tracks of the
    participants present in window K go to ``tmp/x-K-J.arrow`` and ``tmp/y-K-J.arrow``
    (where the window's derivations read them). Returns the windows with states (their cores),
    the rows and the peak memory."""
    from aveas_format.io.writer import prepare_table
    from aveas_format.schema.tables import TABLES

    states = feather.read_table(Path(tmp) / f"c-{j}.arrow")
    rec = _window_recording(path, states)
    t = prepare_table(_run(rec, "kinematics", params), TABLES["derived/kinematics"])
    (Path(out) / "kinematics").mkdir(parents=True, exist_ok=True)
    _write_part(t, Path(out) / "kinematics" / f"part-{j:06d}.parquet")
    pid, tm = states.column("participant_id").to_numpy(), states.column("time").to_numpy()
    cores: list[int] = []
    if len(pid):
        starts = np.r_[0, np.flatnonzero(np.diff(pid)) + 1]  # whole tracks, sorted by id
        lo = np.floor(np.minimum.reduceat(tm, starts) / window_s).astype(np.int64)
        hi = np.floor(np.maximum.reduceat(tm, starts) / window_s).astype(np.int64)
        cores = np.unique(np.floor(tm / window_s).astype(np.int64)).tolist()
        track_ids = pid[starts]
        for w in _windows_of(lo, hi):
            ids = pa.array(track_ids[(lo <= w) & (hi >= w)])
            for prefix, table in (("x", states), ("y", t)):
                part = table.filter(pc.is_in(table.column("participant_id"), ids))
                # Arrow IPC with LZ4: written and read back several times faster than Parquet
                feather.write_feather(part, Path(tmp) / f"{prefix}-{w}-{j:06d}.arrow",
                                      compression="lz4")
    return {"rows": t.num_rows, "cores": cores, "peak_kb": _peak_kb()}


def _windows_of(lo: np.ndarray, hi: np.ndarray) -> list[int]:
    """Every window number in some ``[lo, hi]``."""
    if not len(lo):
        return []
    hit = np.zeros(int(hi.max() - lo.min()) + 1, bool)
    base = int(lo.min())
    for a, b in np.unique(np.stack([lo, hi], 1), axis=0):  # one per distinct track span
        hit[a - base:b - base + 1] = True
    return (np.flatnonzero(hit) + base).tolist()


def _window_recording(path: str, states: pa.Table):
    """A recording of the participants of ``states`` (with the source's metadata and map)."""
    from aveas_format.io.reader import open_recording
    from aveas_format.io.recording import Recording

    head = open_recording(path, tables=["participants"], verify=False)
    ids = pa.array(np.unique(states.column("participant_id").to_numpy()))
    parts = head.participants.filter(pc.is_in(head.participants.column("participant_id"), ids))
    return Recording(head.meta.model_copy(deep=True), {"participants": parts, "states": states},
                     head.map_source)


def _params(name: str, params: dict[str, Any]):
    """Derivation ``name``'s parameters: those of the flat ``params`` it has."""
    from aveas_format.derive.registry import derivations

    d = derivations()[name]
    return d.params(**{k: v for k, v in params.items() if k in d.params.model_fields})


def _run(rec, name: str, params: dict[str, Any], **kw: Any) -> pa.Table:
    """Derivation ``name``'s function on ``rec`` with the ``params`` it has (directly: a window
    needs no input hashes, which would serialise its states once per derivation; the parameters
    go into the table's metadata, where the events read the interactions' own); ``kw`` go to the
    function (``core`` of interactions)."""
    import json

    from aveas_format.derive.registry import DERIVED_KEY, derivations

    p = _params(name, params)
    t = derivations()[name].fn(rec, p, **kw)
    return t.replace_schema_metadata({**(t.schema.metadata or {}), DERIVED_KEY: json.dumps(
        {"derivation": name, "parameters": p.model_dump(mode="json")}).encode()})


def _core_rows(t: pa.Table, t0: float, t1: float) -> pa.Table:
    """The rows of ``t`` with ``t0 <= time < t1`` (``t`` itself where all are: the interactions
    of a window have only core rows)."""
    tt = t.column("time")
    lo_hi = pc.min_max(tt)
    if not t.num_rows or (lo_hi["min"].as_py() >= t0 and lo_hi["max"].as_py() < t1):
        return t
    return t.filter(pc.and_(pc.greater_equal(tt, t0), pc.less(tt, t1)))


def _window_task(item: tuple[int, float, float], *, path: str, tmp: str, out: str,
                 params: dict[str, Any], events: bool = True) -> dict[str, Any]:
    """Derive one window and write its core rows; returns its summary rows and counts."""
    from aveas_format.derive.criticality import compute as summary
    from aveas_format.derive.criticality import CriticalityParams
    from aveas_format.derive.events import window_episodes
    from aveas_format.io.writer import prepare_table
    from aveas_format.schema.tables import TABLES

    k, t0, t1 = item
    # the whole tracks of the participants present in the core: a crossing needs both paths up
    # to the crossing point, a leader search the participant's later lanes (its route), however
    # far ahead
    def read(prefix: str) -> pa.Table:
        return pa.concat_tables([feather.read_table(f) for f in
                                 sorted(Path(tmp).glob(f"{prefix}-{k}-*.arrow"))])

    rec = _window_recording(path, read("x"))
    rec.derived["kinematics"] = prepare_table(read("y"), TABLES["derived/kinematics"])
    rec.derived["conflicts"] = _run(rec, "conflicts", params)
    # the pairs of a time step need that step only, and the routes ahead (the later lanes of its
    # participants): the rows of the core's time steps, the later states for the routes only
    for name in ("states", "kinematics"):
        t = rec.states if name == "states" else rec.derived[name]
        t = t.filter(pc.greater_equal(t.column("time"), t0))
        if name == "states":
            rec.states = t
        else:
            rec.derived[name] = t
    rec.derived["interactions"] = _run(rec, "interactions", params, core=(t0, t1))
    counts = {}
    for name in ("interactions", "conflicts"):
        # the core rows only: written, and the window's summary over them (each sample counted
        # once over all windows)
        rec.derived[name] = core = _core_rows(rec.derived[name], t0, t1)
        (Path(out) / name).mkdir(parents=True, exist_ok=True)
        # sorted as the table declares, in small row groups: assembling the table in key order
        # (write_by_windows) reads each participant range from the parts by their statistics
        core = prepare_table(core, TABLES[f"derived/{name}"])
        _write_part(core, Path(out) / name / f"part-{k:06d}.parquet")
        counts[name] = core.num_rows
    # the critical episodes of the core (the collision probabilities follow the tracks beyond
    # it); the events are made of all windows' episodes (derive_by_windows), and the summary's
    # event counts from them (merge_summaries)
    episodes = window_episodes(rec, _params("events", params), (t0, t1)) if events else []
    rec.events = None
    cp = {k_: v for k_, v in params.items() if k_ in CriticalityParams.model_fields}
    s = summary(rec, CriticalityParams(**cp), core=(t0, t1))
    return {"window": k, "counts": counts, "summary": s, "episodes": episodes,
            "peak_kb": _peak_kb()}


def merge_summaries(parts: list[pa.Table], events: pa.Table | None = None) -> pa.Table:
    """One criticality summary from the summaries of disjoint time windows: sums of duration,
    TET, TIT and counts (stds added in quadrature), minima (maxima for DRAC) with their std, time
    and pair, CPI weighted by the observed time; the recording's row from the participants'; the
    event counts and worst events from the recording's ``events`` (assembled from all windows)."""
    from aveas_format.derive.criticality import event_measures, summary_table

    rows = [r for t in parts for r in t.to_pylist() if str(r["scope"]) == "participant"]
    by: dict[int, dict[str, Any]] = {}
    for r in rows:
        m = by.setdefault(r["participant_id"], {"duration_s": 0.0, "tet": 0.0, "tet_var": 0.0,
                                                "tit": 0.0, "tit_var": 0.0, "cpi_num": 0.0,
                                                "cpi_var": 0.0, "ttc_samples_below": 0})
        d = r["duration_s"] or 0.0
        m["duration_s"] += d
        for k in ("tet", "tit"):
            m[k] += r[k] or 0.0
            m[f"{k}_var"] += (r[f"{k}_std"] or 0.0) ** 2
        m["cpi_num"] += (r["cpi"] or 0.0) * d
        m["cpi_var"] += ((r["cpi_std"] or 0.0) * d) ** 2
        m["ttc_samples_below"] += r["ttc_samples_below"]
        for k, worse in (("min_ttc", min), ("max_drac", max), ("min_psd", min), ("min_pet", min)):
            v = r[k]
            if v is not None and (m.get(k) is None or worse(v, m[k]) == v and v != m[k]):
                m[k], m[f"{k}_std"] = v, r[f"{k}_std"]
                if k == "min_ttc":
                    m["min_ttc_time"], m["min_ttc_other_id"] = r["min_ttc_time"], r[
                        "min_ttc_other_id"]
                    m["min_ttc_kind"] = r["min_ttc_kind"]
    ids = np.array(sorted(by), np.int64)

    def col(k, default=np.nan):
        return np.array([by[i].get(k) if by[i].get(k) is not None else default for i in ids],
                        float)

    T = col("duration_s", 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = {"duration_s": T, "tet": col("tet", 0.0), "tet_std": np.sqrt(col("tet_var", 0.0)),
               "tit": col("tit", 0.0), "tit_std": np.sqrt(col("tit_var", 0.0)),
               "cpi": np.where(T > 0, col("cpi_num", 0.0) / T, np.nan),
               "cpi_std": np.where(T > 0, np.sqrt(col("cpi_var", 0.0)) / T, np.nan)}
    for k in ("min_ttc", "min_ttc_std", "min_ttc_time", "max_drac", "max_drac_std", "min_psd",
              "min_psd_std", "min_pet", "min_pet_std"):
        out[k] = col(k)
    out["min_ttc_other_id"] = np.array([by[i].get("min_ttc_other_id")
                                        if by[i].get("min_ttc_other_id") is not None else -1
                                        for i in ids], np.int64)
    out["min_ttc_kind"] = np.array([by[i].get("min_ttc_kind") for i in ids], object)
    out["ttc_samples_below"] = np.array([by[i]["ttc_samples_below"] for i in ids], np.int64)
    counts, worst, rec_worst = event_measures(events, ids)

    def nanarg(v, largest=False):
        if not np.isfinite(v).any():
            return -1
        return int(np.nanargmax(v) if largest else np.nanargmin(v))

    rv: dict[str, Any] = {"duration_s": float(T.sum())}
    k = nanarg(out["min_ttc"])
    for c in ("min_ttc", "min_ttc_std", "min_ttc_time"):
        rv[c] = float(out[c][k]) if k >= 0 else np.nan
    rv["min_ttc_other_id"] = int(out["min_ttc_other_id"][k]) if k >= 0 else -1
    rv["min_ttc_kind"] = out["min_ttc_kind"][k] if k >= 0 else None
    for c, largest in (("max_drac", True), ("min_psd", False), ("min_pet", False)):
        j = nanarg(out[c], largest)
        rv[c] = float(out[c][j]) if j >= 0 else np.nan
        rv[f"{c}_std"] = float(out[f"{c}_std"][j]) if j >= 0 else np.nan
    for c in ("tet", "tit"):
        rv[c] = float(out[c].sum())
        rv[f"{c}_std"] = float(np.sqrt((out[f"{c}_std"] ** 2).sum()))
    tot = rv["duration_s"]
    rv["cpi"] = float(np.nansum(out["cpi"] * T) / tot) if tot > 0 else np.nan
    rv["cpi_std"] = float(np.sqrt(np.nansum((out["cpi_std"] * T) ** 2)) / tot) if tot > 0 else np.nan
    rv["ttc_samples_below"] = int(out["ttc_samples_below"].sum())
    for c in ("near_misses", "conflicts", "hard_braking"):
        rv[c] = counts.get(f"recording_{c}", 0)
    return summary_table(ids, out, counts, worst, rv, rec_worst)


def derive_by_windows(path: str | Path, out_dir: str | Path, *,
                      window_s: float = DEFAULT_WINDOW_S, workers: int | None = 2,
                      progress: bool = False, track_chunk_rows: int = 500_000,
                      events: bool = True, tracks_done: Callable[[], Any] | None = None,
                      **params: Any) -> dict[str, Any]:
    """Derive the criticality measures of the recording at ``path`` into ``out_dir`` (module
    docstring): kinematics per chunk of whole tracks (about ``track_chunk_rows`` states), then
    interactions, conflicts, the events' episodes and the summary per time window, the events
    (``out_dir/events.parquet``: the source's non-derived events and the derived ones) from all
    windows' episodes (``events`` False: none, the summary without event counts); ``params``
    (flat: a parameter name and its value) go to every derivation that has such a parameter;
    ``tracks_done`` is called once ``out_dir/kinematics`` is complete (before the windows).
    Memory per worker grows with the window (and the chunk), not with the recording; the CPU
    time hardly depends on the window (docs/performance.md). Returns counts: windows, rows per
    derived table (``events``: the derived events), the largest worker's peak memory (kB)."""
    from aveas_format.derive.events import from_windows
    from aveas_format.errors import AveasError
    from aveas_format.io.reader import open_recording
    from aveas_format.parallel import run_tasks

    path, out = Path(path), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="aveas-windows-", dir=out))

    def results(fn, items, what):
        for r in run_tasks(fn, items, workers=workers, progress=progress, description=what):
            if not r.ok:
                raise AveasError(f"{what} {r.item}: {r.error}", path=path)
            yield r.value

    try:
        chunks = _track_chunks(path, tmp, track_chunk_rows)
        counts, peak = dict.fromkeys(WINDOW_DERIVATIONS, 0), 0
        fn = functools.partial(_chunk_task, path=str(path), tmp=str(tmp), out=str(out),
                               window_s=window_s, params=params)
        cores: set[int] = set()
        for v in results(fn, chunks, "tracks"):
            counts["kinematics"] += v["rows"]
            cores.update(v["cores"])
            peak = max(peak, v["peak_kb"] or 0)
        for j in chunks:
            (tmp / f"c-{j}.arrow").unlink()
        if tracks_done is not None:
            tracks_done()
        windows = [(k, k * window_s, (k + 1) * window_s) for k in sorted(cores)]
        fn = functools.partial(_window_task, path=str(path), tmp=str(tmp), out=str(out),
                               params=params, events=events)
        done = []
        for v in results(fn, windows, "windows"):
            done.append(v)
            for k, n in v["counts"].items():
                counts[k] += n
            peak = max(peak, v["peak_kb"] or 0)
        # in window order, whichever finished first: the same sums to the last bit on every run
        done.sort(key=lambda v: v["window"])
        sums = [v["summary"] for v in done]
        episodes = [e for v in done for e in v["episodes"]]
        ev = None
        if events:
            head = open_recording(path, tables=["participants", "events"], verify=False)
            ev = from_windows(head, episodes, _params("events", params))
            pq.write_table(ev, out / "events.parquet")
            counts["events"] = _derived_count(ev)
        else:
            del counts["events"]
        summary = merge_summaries(sums, ev)
        pq.write_table(summary, out / "criticality_summary.parquet")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"windows": len(windows), **counts, "worker_peak_kb": peak,
            "participants": summary.num_rows - 1}


def _derived_count(events: pa.Table) -> int:
    """The derived events of an events table."""
    origin = events.column("origin")
    return int(pc.sum(pc.equal(origin.cast(pa.string()), "derived")).as_py() or 0)


def _pid_ranges(dataset, rows: int) -> list[tuple[int, int]]:
    """Consecutive participant-id ranges ``(lo, hi)`` (inclusive) of about ``rows`` rows each
    (a participant's rows are never split)."""
    vals, cnts = [], []
    for frag in dataset.get_fragments():  # a part at a time: not the whole column in memory
        vc = pc.value_counts(frag.to_table(columns=["participant_id"]).column("participant_id"))
        vals.append(vc.field("values").to_numpy())
        cnts.append(vc.field("counts").to_numpy())
    if not vals or not sum(len(v) for v in vals):
        return []
    ids, inv = np.unique(np.concatenate(vals), return_inverse=True)
    n = np.bincount(inv.ravel(), weights=np.concatenate(cnts)).astype(np.int64)
    piece = np.cumsum(n) // max(rows, 1)
    starts = np.r_[0, np.flatnonzero(np.diff(piece)) + 1]
    ends = np.r_[starts[1:], len(ids)] - 1
    return [(int(ids[a]), int(ids[b])) for a, b in zip(starts, ends)]


def _assemble(parts: Path, spec, dest: Path, provenance: bytes) -> tuple[int, str]:
    """Write the derived table whose window parts are in ``parts`` as one Parquet file ``dest``
    in the table's key order, a participant range at a time; return (rows, SHA-256)."""
    import pyarrow.dataset as ds

    from aveas_format.derive.registry import DERIVED_KEY, empty_table
    from aveas_format.io.writer import ROW_GROUP_ROWS, parquet_options, prepare_table
    from aveas_format.parallel import read_ahead

    files = sorted(parts.glob("part-*.parquet")) if parts.is_dir() else []
    dest.parent.mkdir(parents=True, exist_ok=True)
    schemas = [pq.read_schema(f) for f in files]
    data = ds.dataset([str(f) for f in files], schema=pa.unify_schemas(
        schemas, promote_options="permissive")) if files else None
    writer, rows = None, 0
    pairs = None
    if data is not None and "conflict_id" in data.schema.names and spec.name == "derived/conflicts":
        # the windows number their conflicts each on their own: renumber by the pair of ids
        # (derive.conflicts.pair_rank) over the whole recording
        ids = data.to_table(columns=["participant_id", "other_id"])
        a, b = (ids.column(c).to_numpy() for c in ("participant_id", "other_id"))
        pairs = np.unique(np.minimum(a, b) * (1 << 32) + np.maximum(a, b))

    def load(rng: tuple[int, int] | None) -> pa.Table:
        if rng is None:
            t = data.to_table() if data is not None else empty_table(spec.name)
        else:
            f = pc.field("participant_id")
            t = data.to_table(filter=(f >= rng[0]) & (f <= rng[1]))
        if pairs is not None and t.num_rows:
            a, b = (t.column(c).to_numpy() for c in ("participant_id", "other_id"))
            cid = np.searchsorted(pairs, np.minimum(a, b) * (1 << 32) + np.maximum(a, b))
            t = t.set_column(t.schema.get_field_index("conflict_id"), "conflict_id",
                             pa.array(cid.astype(np.int64)))
        return prepare_table(t, spec)

    try:
        pieces = (_pid_ranges(data, ASSEMBLE_ROWS) if data is not None else []) or [None]
        # the next range read and sorted while this one is encoded and written (both release
        # the GIL: the assembly, serial after the windows, on two cores)
        for t in read_ahead(load, pieces):
            if writer is None:
                schema, options = parquet_options(t.schema.with_metadata(
                    {**(t.schema.metadata or {}), DERIVED_KEY: provenance}), spec)
                writer = pq.ParquetWriter(str(dest), schema, **options)
            t = t.select(schema.names).cast(schema)
            writer.write_table(t, row_group_size=ROW_GROUP_ROWS)
            rows += t.num_rows
    finally:
        if writer is not None:
            writer.close()
    from aveas_format.io.container import Container

    with Container(dest.parent) as c:
        return rows, c.sha256(dest.name)


def write_by_windows(src: str | Path, path: str | Path, *, window_s: float = DEFAULT_WINDOW_S,
                     workers: int | None = 2, overwrite: bool = False,
                     progress: bool = False, events: bool = True, **params: Any) -> dict[str, Any]:
    """The recording at ``src`` with its criticality tables (``WINDOW_TABLES``) derived window by
    window (:func:`derive_by_windows`), written to ``path`` (directory form, or ZIP when the name
    ends in ``.zip``) without holding the recording in memory: the source's other files are
    copied as they are, each derived table is assembled from the windows' parts one participant
    range at a time, and ``recording.json`` gets their table entries and provenance as
    :func:`aveas_format.derive.derive` writes them. Atomic; an existing ``path`` is replaced only
    with ``overwrite``; ``events`` False: the events are not derived (the source's are copied).
    Returns :func:`derive_by_windows`' counts and the derived table names."""
    import json
    import uuid
    import zipfile
    from datetime import datetime, timezone

    from aveas_format.derive.registry import DERIVED_KEY, derivations
    from aveas_format.errors import RecordingIOError
    from aveas_format.io.container import Container, sha256_of
    from aveas_format.io.reader import open_recording
    from aveas_format.io.writer import check_target, move_into_place, parquet_bytes, prepare_table
    from aveas_format.parallel import processes
    from aveas_format.schema.metadata import DerivedEntry, TableEntry
    from aveas_format.schema.tables import TABLES
    from aveas_format.schema.versions import FORMAT_VERSION

    src, path = Path(src), Path(path)
    parent = check_target(path, overwrite)
    head = open_recording(src, tables=["participants"], verify=False)
    meta = head.meta.model_copy(deep=True)
    reg = derivations()
    names = [n for n in WINDOW_TABLES if events or n != "events"]
    ours = {reg[n].table for n in names}
    work = parent / f".{path.name}.work-{uuid.uuid4().hex[:8]}"
    tmp = parent / f".{path.name}.tmp-{uuid.uuid4().hex[:8]}"
    shas = {n: e.sha256 for n, e in meta.tables.items() if n not in ours}
    created = datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")

    def provenance(n: str) -> tuple[bytes, dict, dict, str]:
        d, p = reg[n], _params(n, params)
        # the windows derive no encroachments: the events are not made of the source's
        inputs = {t: shas[t] for t in d.inputs() if t in shas
                  and not (n == "events" and t == "derived/encroachments")}
        pdump, method = p.model_dump(mode="json"), d.method(p)
        return (json.dumps({"derivation": n, "method": method, "version": d.version,
                            "parameters": pdump, "inputs": inputs}).encode(), inputs, pdump, method)

    # the kinematics (an input of the others' provenance) are assembled while the windows are
    # derived: the parent's serial work after them is the other tables'. In a process of its
    # own, started before the windows' workers (none is forked while a thread of this one runs);
    # where the windows run in this process (workers=1, a pool's worker), after them
    early: dict[str, Future] = {}
    pool = ProcessPoolExecutor(1) if processes(workers) > 1 else None

    def tracks_done() -> None:
        if pool is None:
            return
        spec = TABLES[reg["kinematics"].table]
        early["kinematics"] = pool.submit(_assemble, work / "kinematics", spec, tmp / spec.file,
                                          provenance("kinematics")[0])
    try:
        work.mkdir()
        tmp.mkdir()
        info = derive_by_windows(src, work, window_s=window_s, workers=workers,
                                 progress=progress, events=events, tracks_done=tracks_done,
                                 **params)
        with Container(src) as c:
            for name in c.names():
                if name == "recording.json" or name.removesuffix(".parquet") in ours:
                    continue
                target = tmp / name
                target.parent.mkdir(parents=True, exist_ok=True)
                with c.input_file(name) as f, open(target, "wb") as g:
                    while block := f.read(1 << 22):
                        g.write(block)
        for n in names:
            d = reg[n]
            prov, inputs, pdump, method = provenance(n)
            spec = TABLES[d.table]
            if n in early:
                rows, sha = early.pop(n).result()
            elif n in ("events", "criticality_summary"):
                t = prepare_table(pq.read_table(work / f"{n}.parquet"), spec)
                t = t.replace_schema_metadata({**(t.schema.metadata or {}), DERIVED_KEY: prov})
                buf = parquet_bytes(t, spec)
                (tmp / spec.file).parent.mkdir(parents=True, exist_ok=True)
                (tmp / spec.file).write_bytes(memoryview(buf))
                rows, sha = t.num_rows, sha256_of(buf)
            else:
                rows, sha = _assemble(work / n, spec, tmp / spec.file, prov)
            meta.tables[d.table] = TableEntry(rows=rows, sha256=sha)
            shas[d.table] = sha
            # derived events carry their provenance in the events table only (as derive writes)
            meta.derived = [e for e in meta.derived if e.table != d.table] + ([] if n == "events"
                                                                               else [DerivedEntry(
                table=d.table, method=method, version=d.version, parameters=pdump,
                created=created, inputs=inputs)])
        meta.format_version = FORMAT_VERSION
        (tmp / "recording.json").write_text(meta.to_json())
        if path.name.endswith(".zip"):
            z = parent / f".{path.name}.zip-{uuid.uuid4().hex[:8]}"
            files = sorted((q.relative_to(tmp).as_posix() for q in tmp.rglob("*") if q.is_file()),
                           key=lambda n: n != "recording.json")
            with zipfile.ZipFile(z, "w", compression=zipfile.ZIP_STORED) as zf:
                for n in files:
                    zi = zipfile.ZipInfo(n, date_time=(1980, 1, 1, 0, 0, 0))
                    big = (tmp / n).stat().st_size >= 1 << 31
                    with open(tmp / n, "rb") as f, zf.open(zi, "w", force_zip64=big) as g:
                        shutil.copyfileobj(f, g, 1 << 22)
            shutil.rmtree(tmp, ignore_errors=True)
            tmp = z
        move_into_place(tmp, path, overwrite)
    except OSError as e:
        raise RecordingIOError(f"cannot write: {e.strerror or e}", path=path) from None
    finally:
        if pool is not None:  # (an error before the kinematics were taken: their writing ends first)
            pool.shutdown()
        shutil.rmtree(work, ignore_errors=True)
        if tmp.is_dir():
            shutil.rmtree(tmp, ignore_errors=True)
        elif tmp.exists():
            tmp.unlink(missing_ok=True)
    return {**info, "recording": str(path), "derived": names,
            "tables": {reg[n].table: meta.tables[reg[n].table].rows for n in names}}


__all__ = ["DEFAULT_WINDOW_S", "WINDOW_DERIVATIONS", "WINDOW_TABLES", "derive_by_windows",
           "merge_summaries", "write_by_windows"]
