"""Figures of a recording (matplotlib, headless): the map with trajectories and findings, speed and
acceleration histograms per class, the sample rate over time.

Every function takes a :class:`~aveas_format.io.recording.Recording` and returns a matplotlib
``Figure``; :func:`figures` returns all of them by name and :func:`save_figures` writes them as PNG.
Large recordings are subsampled for drawing (``max_points``); histograms use every sample, and
:func:`open_for_figures` reads a bounded subset of a large recording. The map underneath is drawn by
:func:`aveas_format.plot.map.plot_map`. Figures are standalone ``Figure`` objects (no pyplot state),
so drawing never switches the backend of an interactive session.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from matplotlib.figure import Figure

from aveas_format.plot.map import BACKGROUND_LANE_COLORS, plot_map
from aveas_format.safeio import save_figure_atomic

_SEV_STYLE = {"error": ("#d62728", "x"), "warning": ("#ff7f0e", "^"), "info": ("#1f77b4", "o")}


def _states(rec) -> dict[str, np.ndarray] | None:
    s = rec.states
    if s is None or not s.num_rows:
        return None
    out = {}
    for c in ("participant_id", "time", "x", "y", "vx", "vy"):
        if c not in s.column_names:
            return None
        a = s.column(c)
        if a.null_count:
            a = a.cast(pa.float64()).fill_null(np.nan)
        out[c] = np.asarray(a.to_numpy(zero_copy_only=False))
    order = np.lexsort((out["time"], out["participant_id"]))
    if np.any(np.diff(order) != 1):
        out = {k: v[order] for k, v in out.items()}
    return out


def _classes(rec, pid: np.ndarray) -> np.ndarray:
    p = rec.participants
    if p is None or "class" not in p.column_names:
        return np.full(len(pid), "unknown", dtype=object)
    ids = p.column("participant_id").to_numpy()
    cls = np.array(p.column("class").cast(pa.string()).to_pylist(), dtype=object)
    order = np.argsort(ids)
    pos = np.clip(np.searchsorted(ids[order], pid), 0, len(ids) - 1)
    found = ids[order][pos] == pid
    return np.where(found, cls[order][pos], "unknown")


def map_figure(rec, findings: Iterable[Any] = (), max_points: int = 200_000) -> Figure:
    """The map underneath (:func:`~aveas_format.plot.map.plot_map`, lanes by type in the light
    ``BACKGROUND_LANE_COLORS``, road ids), the trajectories (subsampled) and the
    findings with a position (x/y, or the state row they name)."""
    fig = Figure(figsize=(11, 6), dpi=100)
    ax = fig.subplots()
    try:
        plot_map(rec.map, ax, step=2.0, lane_colors=BACKGROUND_LANE_COLORS,
                 lane_edges=("#b0b0b0", 0.3), reference_lines=False, junctions=False, legend=False,
                 title="")
    except Exception:  # noqa: BLE001 — a figure without the map is still useful
        ax.text(0.01, 0.99, "map not available", transform=ax.transAxes, va="top")
    st = _states(rec)
    if st is not None:
        n = len(st["x"])
        step = max(1, n // max_points)
        pid = st["participant_id"][::step]
        x, y = st["x"][::step], st["y"][::step]
        brk = np.flatnonzero(np.diff(pid) != 0) + 1
        xs = np.insert(x.astype(float), brk, np.nan)
        ys = np.insert(y.astype(float), brk, np.nan)
        ax.plot(xs, ys, linewidth=0.6, color="#1f4e79", alpha=0.6, zorder=2.5)
    pts = _finding_points(rec, findings, st)
    for sev, (color, marker) in _SEV_STYLE.items():
        sel = [(px, py) for s, px, py in pts if s == sev]
        if sel:
            arr = np.array(sel)
            ax.scatter(arr[:, 0], arr[:, 1], c=color, marker=marker, s=40, zorder=6,
                       label=f"{sev} ({len(sel)})")
    if pts:
        ax.legend(loc="upper right", fontsize=8)
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    # equal axes (plot_map's), unless a long straight road would become a thin strip
    ratio = max(x1 - x0, 1e-9) / max(y1 - y0, 1e-9)
    ax.set_aspect("equal" if ratio < 8 else "auto", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{rec.meta.recording_id}: lanes, trajectories and located findings")
    fig.tight_layout()
    return fig


def _finding_points(rec, findings: Iterable[Any], st) -> list[tuple[str, float, float]]:
    out = []
    rows_x = rows_y = None
    if rec.states is not None and "x" in rec.states.column_names:
        rows_x = rec.states.column("x")
        rows_y = rec.states.column("y")
    for f in findings:
        loc = f.location
        sev = f.severity.value if hasattr(f.severity, "value") else str(f.severity)
        if loc.x is not None and loc.y is not None:
            out.append((sev, loc.x, loc.y))
        elif loc.table == "states" and loc.row is not None and rows_x is not None and \
                0 <= loc.row < len(rows_x):
            px, py = rows_x[loc.row].as_py(), rows_y[loc.row].as_py()
            if px is not None and py is not None:
                out.append((sev, float(px), float(py)))
    return out


def _per_class_hist(ax, values: np.ndarray, cls: np.ndarray, bins: np.ndarray, xlabel: str) -> None:
    ok = np.isfinite(values)
    for c in sorted(set(cls[ok])):
        sel = ok & (cls == c)
        ax.hist(values[sel], bins=bins, histtype="step", linewidth=1.4,
                label=f"{c} (n={int(sel.sum())})", density=True)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("density")
    if ok.any():
        ax.legend(fontsize=8)


def speed_histogram(rec) -> Figure:
    """Distribution of speed over ground (from vx, vy) per class."""
    fig = Figure(figsize=(6, 4), dpi=100)
    ax = fig.subplots()
    st = _states(rec)
    if st is not None:
        v = np.hypot(st["vx"], st["vy"])
        top = np.nanpercentile(v, 99.9) if np.isfinite(v).any() else 1.0
        _per_class_hist(ax, v, _classes(rec, st["participant_id"]),
                        np.linspace(0, max(top, 1.0) * 1.05, 60), "speed [m/s]")
    ax.set_title("Speed per class")
    fig.tight_layout()
    return fig


def acceleration_histogram(rec, window: float = 0.5) -> Figure:
    """Distribution of the planar acceleration magnitude (velocity differences over ``window`` s,
    the estimate of the kinematics rules) per class."""
    fig = Figure(figsize=(6, 4), dpi=100)
    ax = fig.subplots()
    st = _states(rec)
    if st is not None and len(st["time"]) > 1:
        pid, t = st["participant_id"], st["time"]
        seg = np.r_[0, np.cumsum(np.diff(pid) != 0)]
        span = float(np.nanmax(t) - np.nanmin(t)) + 2 * window + 1
        key = seg * span + (t - np.nanmin(t))
        j = np.searchsorted(key, key + window)
        ok = j < len(t)
        jj = np.minimum(j, len(t) - 1)
        ok &= seg[jj] == seg
        i = np.flatnonzero(ok)
        jj = jj[i]
        a = np.hypot(st["vx"][jj] - st["vx"][i], st["vy"][jj] - st["vy"][i]) / (t[jj] - t[i])
        top = np.nanpercentile(a, 99.9) if len(a) and np.isfinite(a).any() else 1.0
        _per_class_hist(ax, a, _classes(rec, pid[i]), np.linspace(0, max(top, 1.0) * 1.05, 60),
                        f"|acceleration| over {window:g} s [m/s²]")
    ax.set_title("Acceleration per class")
    fig.tight_layout()
    return fig


def sample_rate_figure(rec, bin_s: float = 1.0) -> Figure:
    """Mean sample rate per participant present, per time bin, against nominal_rate_hz."""
    fig = Figure(figsize=(8, 3.5), dpi=100)
    ax = fig.subplots()
    st = _states(rec)
    if st is not None:
        t = st["time"]
        ok = np.isfinite(t)
        b = np.floor(t[ok] / bin_s).astype(np.int64)
        b -= b.min() if len(b) else 0
        samples = np.bincount(b)
        pairs = np.unique(b * (int(st["participant_id"].max()) + 1) + st["participant_id"][ok])
        present = np.bincount(pairs // (int(st["participant_id"].max()) + 1), minlength=len(samples))
        rate = np.where(present > 0, samples / np.maximum(present, 1) / bin_s, np.nan)
        tb = (np.arange(len(samples)) + 0.5) * bin_s + (np.floor(np.nanmin(t) / bin_s) * bin_s)
        ax.step(tb, rate, where="mid", label="observed (per participant)")
    ax.axhline(rec.meta.nominal_rate_hz, color="#d62728", linestyle="--",
               label=f"nominal {rec.meta.nominal_rate_hz:g} Hz")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("samples / s")
    ax.set_ylim(bottom=0)
    ax.legend(fontsize=8)
    ax.set_title("Sample rate over time")
    fig.tight_layout()
    return fig


#: figures of a larger recording are drawn from a subset of its participants of about this many rows
FIGURE_ROWS = 2_000_000
_FIGURE_COLUMNS = ["x", "y", "vx", "vy"]


def open_for_figures(path: str | Path, report: Any = None, max_rows: int = FIGURE_ROWS):
    """The recording as the figures need it: participants and the state columns they draw. Of a
    recording with more than ``max_rows`` states, every k-th participant is read (the figures say
    so), and the positions of findings located by state row only are read from their row groups
    (written into the findings' ``x``/``y``), so memory stays bounded."""
    from aveas_format.io.container import Container
    from aveas_format.io.reader import open_recording

    head = open_recording(path, tables=["participants"], verify=False)
    entry = head.meta.tables.get("states")
    ids = None
    if entry is not None and entry.rows > max_rows and head.participants.num_rows:
        pids = np.sort(head.participants.column("participant_id").to_numpy())
        k = -(-entry.rows // max_rows)
        ids = pids[::k].tolist()
    rec = open_recording(path, tables=["participants", "states"],
                         columns={"states": _FIGURE_COLUMNS}, participants=ids, verify=False)
    if ids is not None:
        rec.__dict__["figure_note"] = (f"drawn from every {k}th participant ({len(ids)} of "
                                       f"{head.participants.num_rows}; {rec.states.num_rows:,} of "
                                       f"{entry.rows:,} state rows)")
        if report is not None:
            with Container(path) as c:
                _locate_state_rows(c, report)
    return rec


def _locate_state_rows(container, report: Any) -> None:
    """Fill x/y of sampled findings that name a states row but no position, reading only the row
    groups that hold those rows."""
    import pyarrow.parquet as pq

    todo = [f for f in report.findings() if f.location.table == "states"
            and f.location.row is not None and (f.location.x is None or f.location.y is None)]
    if not todo:
        return
    pf = pq.ParquetFile(container.input_file("states.parquet"))
    md = pf.metadata
    ends = np.cumsum([md.row_group(g).num_rows for g in range(md.num_row_groups)])
    rows = np.array([f.location.row for f in todo], dtype=np.int64)
    groups = np.searchsorted(ends, rows, side="right")
    for g in np.unique(groups[groups < len(ends)]):
        t = pf.read_row_group(int(g), columns=["x", "y"])
        start = ends[g] - t.num_rows
        for f, r, gg in zip(todo, rows, groups):
            if gg == g:
                x, y = t.column("x")[int(r - start)].as_py(), t.column("y")[int(r - start)].as_py()
                if x is not None and y is not None:
                    f.location.x, f.location.y = float(x), float(y)


def figures(rec, findings: Iterable[Any] = ()) -> dict[str, Figure]:
    """Every report figure by name (``map``, ``speed``, ``acceleration``, ``sample_rate``)."""
    return {
        "map": map_figure(rec, list(findings)),
        "speed": speed_histogram(rec),
        "acceleration": acceleration_histogram(rec),
        "sample_rate": sample_rate_figure(rec),
    }


def save_figures(rec, outdir: str | Path, findings: Iterable[Any] = ()) -> list[Path]:
    """Write every figure as ``NAME.png`` into ``outdir`` (created); returns the paths."""
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, fig in figures(rec, findings).items():
        paths.append(save_figure_atomic(fig, out / f"{name}.png"))
    return paths


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG bytes (the HTML report inlines them)."""
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return buf.getvalue()
