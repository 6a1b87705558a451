"""Every criticality measure of a recording too large for memory, by time window
(docs/derive.md "Large recordings").

:func:`derive_by_windows` reads ``states.parquet`` once, row group by row group, and splits it into
time windows (each with ``margin_s`` of context on both sides: the kinematics smoother's and the
pairs' lead-in) stored as temporary Parquet files; then each window is derived on its own
(``kinematics``, ``interactions``, ``conflicts``, the window's criticality summary), in parallel
worker processes, and the rows of its core ``[t0, t1)`` are written as parts of the derived tables:
``OUT/kinematics/part-K.parquet``, ``OUT/interactions/...``, ``OUT/conflicts/...`` (a Parquet
dataset each). The windows' summaries merge into ``OUT/criticality_summary.parquet`` (sums of
TET, TIT, observed time and counts; minima with their std, time and pair; CPI weighted by time).
Memory is bounded by one row group plus one window per worker, whatever the recording's length.

Differences from deriving the whole recording at once (tests/derive/test_streamed.py): the
kinematics smoother sees a window's tracks only and chooses its jerk density per track window by
maximum likelihood, so smoothed speeds (and the TTC from them) differ by a fraction of their std
(0.15 std median on the noisy sample highway in 8-s windows; identical rows with
``velocities="states"``); a pair's
TTC episode cut by a window boundary is two episodes for the TET/TIT Monte Carlo std (their
variances add); a crossing is found where both paths fall into one window (with the margin).
"""

from __future__ import annotations

import functools
import shutil
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

#: the derivations run per window
WINDOW_DERIVATIONS = ("kinematics", "interactions", "conflicts")


def _peak_kb() -> int | None:
    try:
        for ln in Path("/proc/self/status").read_text().splitlines():
            if ln.startswith("VmHWM"):
                return int(ln.split()[1])
    except OSError:
        return None
    return None


def _split(path: Path, tmp: Path, window_s: float, margin_s: float) -> list[tuple[int, float, float]]:
    """Write the states of each window (core plus margins) to ``tmp/w-K.parquet``; return
    ``(K, t0, t1)`` of the windows with states in their core."""
    from aveas_format.io.container import Container

    writers: dict[int, pq.ParquetWriter] = {}
    cores: set[int] = set()  # windows with states in their core (not only in a margin)
    with Container(path) as c:
        pf = pq.ParquetFile(c.input_file("states.parquet"))
        for g in range(pf.metadata.num_row_groups):
            rg = pf.read_row_group(g)
            t = rg.column("time").to_numpy()
            lo = np.floor((t - margin_s) / window_s).astype(np.int64)
            hi = np.floor((t + margin_s) / window_s).astype(np.int64)
            cores.update(np.unique(np.floor(t / window_s).astype(np.int64)).tolist())
            for k in np.unique(np.r_[lo, hi]):
                part = rg.filter(pa.array((lo <= k) & (hi >= k)))
                if not part.num_rows:
                    continue
                if k not in writers:
                    writers[int(k)] = pq.ParquetWriter(tmp / f"w-{int(k)}.parquet", part.schema)
                writers[int(k)].write_table(part)
    for w in writers.values():
        w.close()
    return [(k, k * window_s, (k + 1) * window_s) for k in sorted(writers) if k in cores]


def _window_task(item: tuple[int, float, float], *, path: str, tmp: str, out: str,
                 params: dict[str, Any]) -> dict[str, Any]:
    """Derive one window and write its core rows; returns its summary rows and counts."""
    from aveas_format.derive.criticality import compute as summary
    from aveas_format.derive.criticality import CriticalityParams
    from aveas_format.derive.registry import derivations
    from aveas_format.io.reader import open_recording
    from aveas_format.io.recording import Recording

    k, t0, t1 = item
    head = open_recording(path, tables=["participants"], verify=False)
    states = pq.read_table(Path(tmp) / f"w-{k}.parquet")
    ids = pa.array(np.unique(states.column("participant_id").to_numpy()))
    parts = head.participants.filter(pc.is_in(head.participants.column("participant_id"), ids))
    rec = Recording(head.meta.model_copy(deep=True), {"participants": parts, "states": states},
                    head.map_source)
    # the derivations' functions directly: a window needs no provenance (input hashes would
    # serialise its states once per derivation)
    reg = derivations()
    for name in WINDOW_DERIVATIONS:
        d = reg[name]
        p = d.params(**{k_: v for k_, v in params.items() if k_ in d.params.model_fields})
        rec.derived[name] = d.fn(rec, p)
    counts = {}
    for name in WINDOW_DERIVATIONS:
        t = rec.derived[name]
        tt = t.column("time")
        core = t.filter(pc.and_(pc.greater_equal(tt, t0), pc.less(tt, t1)))
        (Path(out) / name).mkdir(parents=True, exist_ok=True)
        pq.write_table(core, Path(out) / name / f"part-{k:06d}.parquet")
        counts[name] = core.num_rows
    # the window's summary over its core rows only (each sample counted once over all windows)
    st = rec.states.column("time")
    rec.states = rec.states.filter(pc.and_(pc.greater_equal(st, t0), pc.less(st, t1)))
    for name in ("interactions", "conflicts"):
        t = rec.derived[name]
        rec.derived[name] = t.filter(pc.and_(pc.greater_equal(t.column("time"), t0),
                                             pc.less(t.column("time"), t1)))
    rec.events = None
    cp = {k_: v for k_, v in params.items() if k_ in CriticalityParams.model_fields}
    s = summary(rec, CriticalityParams(**cp))
    return {"window": k, "counts": counts, "summary": s, "peak_kb": _peak_kb()}


def merge_summaries(parts: list[pa.Table]) -> pa.Table:
    """One criticality summary from the summaries of disjoint time windows: sums of duration,
    TET, TIT and counts (stds added in quadrature), minima (maxima for DRAC) with their std, time
    and pair, CPI weighted by the observed time; the recording's row from the participants'."""
    from aveas_format.derive.criticality import _table

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
    n = len(ids)

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
    counts = {"near_misses": np.zeros(n, np.int64), "hard_braking": np.zeros(n, np.int64)}

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
    rv["near_misses"] = rv["hard_braking"] = 0
    return _table(ids, out, counts, [[] for _ in range(n)], rv, [])


def derive_by_windows(path: str | Path, out_dir: str | Path, *, window_s: float = 300.0,
                      margin_s: float = 5.0, workers: int | None = 2,
                      **params: Any) -> dict[str, Any]:
    """Derive the criticality measures of the recording at ``path`` window by window into
    ``out_dir`` (module docstring); ``params`` (flat: a parameter name and its value) go to every
    derivation that has such a parameter. Windows of a few minutes keep the per-window overhead
    (the kinematics smoother steps through a window's samples in lockstep) small against the
    work; memory grows with the window, not with the recording. Returns counts: windows, rows per derived table, the
    largest worker's peak memory (kB)."""
    from aveas_format.errors import AveasError
    from aveas_format.parallel import run_tasks

    path, out = Path(path), Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix="aveas-windows-", dir=out))
    try:
        windows = _split(path, tmp, window_s, margin_s)
        fn = functools.partial(_window_task, path=str(path), tmp=str(tmp), out=str(out),
                               params=params)
        sums, counts, peak = [], dict.fromkeys(WINDOW_DERIVATIONS, 0), 0
        for r in run_tasks(fn, windows, workers=workers, description="windows"):
            if not r.ok:
                raise AveasError(f"window {r.item}: {r.error}", path=path)
            sums.append(r.value["summary"])
            for k, v in r.value["counts"].items():
                counts[k] += v
            peak = max(peak, r.value["peak_kb"] or 0)
        summary = merge_summaries(sums)
        pq.write_table(summary, out / "criticality_summary.parquet")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"windows": len(windows), **counts, "worker_peak_kb": peak,
            "participants": summary.num_rows - 1}


__all__ = ["WINDOW_DERIVATIONS", "derive_by_windows", "merge_summaries"]
