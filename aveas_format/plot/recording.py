"""Figures of a recording (matplotlib, headless): the map with trajectories and findings, speed and
longitudinal acceleration histograms per class, the sample rate over time.

Every function takes a :class:`~aveas_format.io.recording.Recording` and returns a matplotlib
``Figure``; :func:`figures` returns all of them by name and :func:`save_figures` writes them as PNG.
Large recordings are subsampled for drawing (``max_points``); histograms use every sample, and
:func:`open_for_figures` reads a bounded subset of a large recording. The map underneath is drawn by
:func:`aveas_format.plot.map.plot_map`. Figures are standalone ``Figure`` objects (no pyplot state),
so drawing never switches the backend of an interactive shell or notebook.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from aveas_format.errors import require
from aveas_format.io.arrow import column_numpy
from aveas_format.plot.map import BACKGROUND_LANE_COLORS, plot_map
from aveas_format.safeio import save_figure_atomic

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

#: colour of each severity (findings are drawn in it; their marker shape is their rule's)
SEVERITY_COLORS = {"error": "#d62728", "warning": "#ff7f0e", "info": "#1f77b4"}
#: marker shapes given to the rules with located findings, in the order of the legend
_MARKERS = ("X", "^", "o", "s", "D", "v", "P", "*", "<", ">", "h", "p", "d", "8")
#: colour of each participant class (the 13 classes of the taxonomy), distinguishable on the
#: light lanes: vehicles in blues/greens/browns, vulnerable road users in reds/purples
CLASS_COLORS: dict[str, str] = {
    "car": "#1f4e9c", "van": "#17becf", "truck": "#2ca02c", "bus": "#8c564b",
    "motorcycle": "#bcbd22", "trailer": "#7f7f7f", "railvehicle": "#393b79",
    "bicycle": "#e377c2", "pedestrian": "#d62728", "mobility_device": "#9467bd",
    "pushable_pullable": "#ff9896", "animal": "#ff7f0e", "other": "#000000",
}
_UNKNOWN_CLASS = "#555555"


def _figure(figsize: tuple[float, float]) -> Figure:
    """A standalone matplotlib figure (no pyplot state); matplotlib is the ``[plot]`` extra, so
    this module imports without it (the HTML report then has no figures and says why)."""
    require("matplotlib", extra="plot", what="drawing figures")
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, dpi=100, layout="constrained")


def recording_name(rec) -> str:
    """What a person calls the recording: its ``title``, else its file name, else its
    ``recording_id`` (often a UUID)."""
    title = getattr(rec.meta, "title", None)
    if title:
        return str(title)
    path = getattr(rec, "path", None)
    if path:
        name = Path(str(path)).name
        for suffix in (".aveas.zip", ".aveas"):
            if name.endswith(suffix):
                return name[: -len(suffix)]
        return name
    return str(rec.meta.recording_id)


def _states(rec) -> dict[str, np.ndarray] | None:
    """participant_id (int64: ids may need all 64 bits), time, x, y, vx, vy (float64, nulls as
    NaN) in (participant_id, time) order; rows without a participant id are left out."""
    s = rec.states
    if s is None or not s.num_rows:
        return None
    if any(c not in s.column_names for c in ("participant_id", "time", "x", "y", "vx", "vy")):
        return None
    if s.column("participant_id").null_count:
        s = s.filter(s.column("participant_id").is_valid())
    out = {"participant_id": np.asarray(s.column("participant_id").to_numpy(zero_copy_only=False),
                                        dtype=np.int64)}
    for c in ("time", "x", "y", "vx", "vy"):
        out[c] = column_numpy(s, c)
    order = np.lexsort((out["time"], out["participant_id"]))
    if np.any(np.diff(order) != 1):
        out = {k: v[order] for k, v in out.items()}
    return out


def _classes(rec, pid: np.ndarray) -> np.ndarray:
    p = rec.participants
    if p is None or "class" not in p.column_names or not p.num_rows:
        return np.full(len(pid), "unknown", dtype=object)
    ids = np.asarray(p.column("participant_id").to_numpy(zero_copy_only=False), dtype=np.int64)
    cls = np.array(p.column("class").cast(pa.string()).to_pylist(), dtype=object)
    order = np.argsort(ids)
    pos = np.clip(np.searchsorted(ids[order], pid), 0, len(ids) - 1)
    found = ids[order][pos] == pid
    return np.where(found, cls[order][pos], "unknown")


def _polygons(geoms) -> list[np.ndarray]:
    """Exterior rings of (multi)polygons, as vertex arrays for a PolyCollection."""
    import shapely

    parts = shapely.get_parts(np.asarray([g for g in geoms if g is not None], dtype=object))
    return [np.asarray(p.exterior.coords) for p in parts
            if p.geom_type == "Polygon" and not p.is_empty]


#: edge colour and hatch of each kind of unobserved region
REGION_STYLES: dict[str, tuple[str, str]] = {
    "occlusion": ("#404040", "///"), "sensor_range": ("#7b3294", "\\\\"),
    "field_of_view": ("#a6611a", "xx"), "sensor_outage": ("#b2182b", ".."),
    "outside_coverage": ("#2166ac", "--"),
}


def _draw_regions(ax, rec, max_regions: int = 5000) -> list[Any]:
    """The coverage polygon (dashed outline) and the unobserved regions, hatched by kind and
    filled the darker the longer they last; a region unobserved for less than a quarter of the
    recording is a dotted outline only (a sensor outage of 0.4 s over the whole area must not
    hide the map); at most ``max_regions`` of each kind are drawn (every k-th); legend handles."""
    import shapely
    from matplotlib.collections import PolyCollection
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    handles: list[Any] = []
    cov = getattr(rec.meta, "coverage", None)
    if cov:
        try:
            rings = _polygons([shapely.from_wkt(cov)])
        except Exception:  # noqa: BLE001 — a malformed coverage is a geo.* finding, not a crash
            rings = []
        if rings:
            ax.add_collection(PolyCollection(rings, facecolors="none", edgecolors="#1b7837",
                                             linewidths=1.2, linestyles="--", zorder=2.2))
            handles.append(Line2D([], [], color="#1b7837", linestyle="--", label="coverage"))
    u = rec.unobserved
    if u is None or not u.num_rows or "geometry" not in u.column_names:
        return handles
    try:
        geoms = shapely.from_wkb(np.asarray(u.column("geometry").to_pylist(), dtype=object))
    except Exception:  # noqa: BLE001 — broken WKB is a structure finding
        return handles
    kinds = (np.asarray(u.column("kind").cast(pa.string()).to_pylist(), dtype=object)
             if "kind" in u.column_names else np.full(u.num_rows, "occlusion", dtype=object))
    ts, te = (column_numpy(u, c, missing=np.nan) for c in ("time_start", "time_end"))
    total = float(rec.meta.duration_s or 0.0) or float(np.nanmax(te) if np.isfinite(te).any() else 1)
    share = np.clip(np.nan_to_num((te - ts) / max(total, 1e-9), nan=1.0), 0.0, 1.0)
    for kind in sorted({str(k) for k in kinds}):
        sel = np.flatnonzero(kinds == kind)
        edge, hatch = REGION_STYLES.get(kind, ("#404040", "//"))
        for brief in (False, True):  # hatched when unobserved for a quarter of the time or more
            part = sel[(share[sel] < 0.25) == brief]
            part = part[::max(1, len(part) // max_regions)]  # e.g. per-frame occlusions
            rings, alphas = [], []
            for k in part:
                for ring in _polygons([geoms[k]]):
                    rings.append(ring)
                    alphas.append(0.04 + 0.3 * share[k])
            if rings:
                ax.add_collection(PolyCollection(
                    rings, facecolors=[(0.4, 0.4, 0.4, a) for a in alphas], edgecolors=edge,
                    linewidths=1.0 if brief else 0.8, linestyles=":" if brief else "-",
                    hatch=None if brief else hatch, zorder=2.3))
        seconds = float(np.nansum(te[sel] - ts[sel]))
        brief = bool((share[sel] < 0.25).all())
        handles.append(Patch(facecolor=(0.4, 0.4, 0.4, 0.08 if brief else 0.25), edgecolor=edge,
                             hatch=None if brief else hatch, linestyle=":" if brief else "-",
                             label=f"unobserved: {kind} ({len(sel)}, {seconds:.3g} s)"))
    return handles


def _trajectory_handles(st, cls: np.ndarray) -> list[Any]:
    """Legend handles of :func:`_draw_trajectories`: each class with its number of participants,
    the arrow and (where someone stands) the dot."""
    from matplotlib.lines import Line2D

    n = len(st["x"])
    starts = np.r_[0, np.flatnonzero(np.diff(st["participant_id"]) != 0) + 1]
    ends = np.r_[starts[1:], n]
    seg_cls = cls[starts]
    handles = [Line2D([], [], color=CLASS_COLORS.get(c, _UNKNOWN_CLASS), linewidth=2,
                      label=f"{c} ({int((seg_cls == c).sum())})")
               for c in sorted(set(seg_cls), key=lambda c: (c == "unknown", c))]
    mid = (starts + ends) // 2
    speed = np.hypot(st["vx"][mid], st["vy"][mid])
    moving = np.isfinite(speed) & (speed > 0.5)
    if moving.any():
        handles.append(Line2D([], [], color="#333333", marker=">", linestyle="-", markersize=6,
                              label="direction of travel"))
    if (np.isfinite(st["x"][mid]) & np.isfinite(st["y"][mid]) & ~moving).any():
        handles.append(Line2D([], [], color="#333333", marker="o", linestyle="none",
                              markersize=4, label="standing (speed < 0.5 m/s)"))
    return handles


def _draw_trajectories(ax, st, cls: np.ndarray, max_points: int, max_arrows: int = 200) -> None:
    """Trajectories coloured by class (subsampled to ``max_points``) with an arrow in the
    direction of travel at the middle of each (up to ``max_arrows`` participants), a dot for a
    participant standing there (legend: :func:`_trajectory_handles`)."""
    n = len(st["x"])
    if n == 0:
        return
    step = max(1, n // max_points)
    starts = np.r_[0, np.flatnonzero(np.diff(st["participant_id"]) != 0) + 1]
    ends = np.r_[starts[1:], n]
    seg_cls = cls[starts]
    for c in sorted(set(seg_cls), key=lambda c: (c == "unknown", c)):
        color = CLASS_COLORS.get(c, _UNKNOWN_CLASS)
        idx = np.flatnonzero(np.repeat(seg_cls == c, ends - starts))[::step]
        pid = st["participant_id"][idx]
        brk = np.flatnonzero(np.diff(pid) != 0) + 1
        ax.plot(np.insert(st["x"][idx], brk, np.nan), np.insert(st["y"][idx], brk, np.nan),
                linewidth=0.7, color=color, alpha=0.75, zorder=2.5)
    # direction of travel: the velocity at the middle sample of each participant's trajectory
    every = max(1, len(starts) // max_arrows)
    mid = ((starts + ends) // 2)[::every]
    vx, vy = st["vx"][mid], st["vy"][mid]
    speed = np.hypot(vx, vy)
    ok = np.isfinite(speed) & (speed > 0.5)
    if ok.any():
        colors = [CLASS_COLORS.get(c, _UNKNOWN_CLASS) for c in seg_cls[::every][ok]]
        ax.quiver(st["x"][mid][ok], st["y"][mid][ok], vx[ok] / speed[ok], vy[ok] / speed[ok],
                  color=colors, angles="xy", scale_units="inches", scale=1 / 0.15,
                  width=0.0025, headwidth=4, headlength=4.5, headaxislength=4, zorder=4,
                  edgecolors="white", linewidths=0.3)
    # a participant standing there has no arrow and a trajectory too short to see: a dot
    still = np.isfinite(st["x"][mid]) & np.isfinite(st["y"][mid]) & ~ok
    if still.any():
        colors = [CLASS_COLORS.get(c, _UNKNOWN_CLASS) for c in seg_cls[::every][still]]
        ax.scatter(st["x"][mid][still], st["y"][mid][still], c=colors, s=16, marker="o",
                   edgecolors="white", linewidths=0.4, zorder=4)


def _draw_findings(ax, pts: list[tuple[str, str, float, float]]) -> list[Any]:
    """Located findings (:func:`_finding_points`): one marker shape per rule, coloured by
    severity; legend handles."""
    from matplotlib.lines import Line2D

    by_rule: dict[str, list[tuple[float, float]]] = {}
    severity: dict[str, str] = {}
    for code, sev, px, py in pts:
        by_rule.setdefault(code, []).append((px, py))
        severity[code] = sev
    rank = {"error": 0, "warning": 1, "info": 2}
    handles = []
    for k, code in enumerate(sorted(by_rule, key=lambda c: (rank.get(severity[c], 3), c))):
        arr = np.array(by_rule[code])
        marker = _MARKERS[k % len(_MARKERS)]
        color = SEVERITY_COLORS.get(severity[code], "#000000")
        ax.scatter(arr[:, 0], arr[:, 1], c=color, marker=marker, s=55, zorder=6,
                   edgecolors="white", linewidths=0.6)
        handles.append(Line2D([], [], color=color, marker=marker, linestyle="none", markersize=8,
                              markeredgecolor="white", label=f"{code} ({len(arr)})"))
    return handles


#: a map figure's data longer than this many times its width is drawn in strips (rows)
STRIP_RATIO = 8.0
#: at most this many strips; each strip is at most about ``STRIP_RATIO`` times as long as wide
MAX_STRIPS = 8


def strips(box: tuple[float, float, float, float]
           ) -> tuple[int, list[tuple[float, float]], tuple[float, float]]:
    """How the map figure shows the data box ``(xmin, ymin, xmax, ymax)`` at equal scale in x and
    y: ``(axis, [(from, to) of each strip along it], (from, to) across)``. ``axis`` is 0 where the
    data run along x, 1 along y. Data less than :data:`STRIP_RATIO` times as long as wide make
    one strip; a 1.5 km motorway 15 m wide is cut into :data:`MAX_STRIPS` strips stacked like
    lines of text (each a little longer than its share, so the strips overlap)."""
    size = (box[2] - box[0], box[3] - box[1])
    axis = 0 if size[0] >= size[1] else 1
    along, across = size[axis], size[1 - axis]
    lo_a, lo_c = box[axis], box[1 - axis]
    pad_c = max(0.15 * across, 3.0)
    ratio = (along + 2 * pad_c) / (across + 2 * pad_c)
    if ratio < STRIP_RATIO:
        pad = max(0.08 * max(along, across), 15.0)
        return axis, [(lo_a - pad, lo_a + along + pad)], (lo_c - pad, lo_c + across + pad)
    n = int(min(MAX_STRIPS, np.ceil(ratio / STRIP_RATIO)))
    pad_a = 0.01 * along + pad_c
    seg = (along + 2 * pad_a) / n
    overlap = 0.03 * seg
    parts = [(lo_a - pad_a + k * seg - overlap, lo_a - pad_a + (k + 1) * seg + overlap)
             for k in range(n)]
    return axis, parts, (lo_c - pad_c, lo_c + across + pad_c)


def map_figure(rec, findings: Iterable[Any] = (), max_points: int = 200_000) -> Figure:
    """The map underneath (:func:`~aveas_format.plot.map.plot_map`, lanes by type in the light
    ``BACKGROUND_LANE_COLORS``), the coverage (dashed) and unobserved regions (hatched), the
    trajectories coloured by class (subsampled) with arrows in the direction of travel, and the
    findings with a position (x/y, or the state row they name), one marker shape per rule and
    coloured by severity. Titled with the recording's name (:func:`recording_name`).

    The axes frame the data (positions, findings, coverage), not the whole map, always at equal
    scale in x and y (a 0.1 m jitter looks like 0.1 m); data much longer than wide (a motorway
    stretch) are drawn in strips stacked like lines of text (:func:`strips`), one axes each."""
    st = _states(rec)
    pts = _finding_points(rec, findings)
    cls = _classes(rec, st["participant_id"]) if st is not None else None
    box = _data_bounds(rec, st, pts)
    if box is None:
        try:
            box = rec.map.bounds
        except Exception:  # noqa: BLE001 — no map and no data: an empty frame
            box = (0.0, 0.0, 100.0, 100.0)
    axis, parts, across = strips(box)
    plot_w = 8.8  # inches beside the legends
    strip_h = plot_w * (across[1] - across[0]) / (parts[0][1] - parts[0][0])
    if len(parts) == 1:
        fig = _figure((12, float(np.clip(strip_h + 1.2, 3.5, 9.0))))
        axes = [fig.subplots()]
    elif axis == 0:
        fig = _figure((12, float(np.clip(len(parts) * (strip_h + 0.45) + 0.9, 3.5, 14.0))))
        axes = list(fig.subplots(len(parts), 1, squeeze=False)[:, 0])
    else:
        fig = _figure((12, 8.0))
        axes = list(fig.subplots(1, len(parts), squeeze=False)[0])
    handles: list[Any] = []
    finding_handles: list[Any] = []
    for k, (ax, (a, b)) in enumerate(zip(axes, parts, strict=True)):
        try:
            plot_map(rec.map, ax, step=2.0, lane_colors=BACKGROUND_LANE_COLORS,
                     lane_edges=("#b0b0b0", 0.3), reference_lines=False, labels=False,
                     junctions=False, legend=False, title="")
        except Exception:  # noqa: BLE001 — a figure without the map is still useful
            ax.text(0.01, 0.99, "map not available", transform=ax.transAxes, va="top")
        region_handles = _draw_regions(ax, rec)
        if st is not None:
            keep = np.ones(len(st["x"]), dtype=bool)
            if len(parts) > 1:  # the samples of this strip (and a little around it)
                v = st["xy"[axis]]
                keep = (v >= a - 0.05 * (b - a)) & (v <= b + 0.05 * (b - a))
            _draw_trajectories(ax, {c: st[c][keep] for c in st}, cls[keep],
                               max_points // len(parts))
        fh = _draw_findings(ax, pts)
        if k == 0:
            handles = (_trajectory_handles(st, cls) if st is not None else []) + region_handles
            finding_handles = fh
        lim_along, lim_across = (ax.set_xlim, ax.set_ylim) if axis == 0 else (ax.set_ylim, ax.set_xlim)
        lim_along(a, b)
        lim_across(*across)
        ax.set_aspect("equal", adjustable="datalim" if len(parts) == 1 else "box")
        ax.tick_params(labelsize=8)
        ax.set_xlabel("x [m]" if len(parts) == 1 or axis == 1 or k == len(parts) - 1 else "")
        ax.set_ylabel("y [m]" if len(parts) == 1 or axis == 0 or k == 0 else "")
    title = recording_name(rec)
    if len(parts) > 1:
        title += f" — {len(parts)} strips along {'xy'[axis]}, equal scale"
    axes[0].set_title(title, fontsize=11)
    if handles:
        fig.legend(handles=handles, title="class (participants), regions", loc="outside right upper",
                   fontsize=8, title_fontsize=8, frameon=False, alignment="left")
    if finding_handles:
        fig.legend(handles=finding_handles, title="located findings: rule (shown)",
                   loc="outside right lower", fontsize=8, title_fontsize=8, frameon=False,
                   alignment="left")
    return fig


def _data_bounds(rec, st, pts: list[tuple[str, str, float, float]]
                 ) -> tuple[float, float, float, float] | None:
    """(xmin, ymin, xmax, ymax) of what the recording observed: the positions, the located
    findings and the coverage polygon; None without any."""
    xs, ys = [], []
    if st is not None:
        ok = np.isfinite(st["x"]) & np.isfinite(st["y"])
        if ok.any():
            xs += [float(st["x"][ok].min()), float(st["x"][ok].max())]
            ys += [float(st["y"][ok].min()), float(st["y"][ok].max())]
    for _, _, px, py in pts:
        if np.isfinite(px) and np.isfinite(py):
            xs.append(px)
            ys.append(py)
    cov = getattr(rec.meta, "coverage", None)
    if cov:
        import shapely

        try:
            b = shapely.from_wkt(cov).bounds
        except Exception:  # noqa: BLE001 — a malformed coverage is a geo.* finding
            b = (np.nan,) * 4
        if all(np.isfinite(b)):
            xs += [b[0], b[2]]
            ys += [b[1], b[3]]
    return (min(xs), min(ys), max(xs), max(ys)) if xs else None


def _finding_points(rec, findings: Iterable[Any]) -> list[tuple[str, str, float, float]]:
    """(code, severity, x, y) of each finding with a position: its x/y, or the states row it
    names."""
    out = []
    rows_x = rows_y = None
    if rec.states is not None and "x" in rec.states.column_names:
        rows_x = rec.states.column("x")
        rows_y = rec.states.column("y")
    for f in findings:
        loc = f.location
        sev = f.severity.value if hasattr(f.severity, "value") else str(f.severity)
        if loc.x is not None and loc.y is not None:
            out.append((f.code, sev, loc.x, loc.y))
        elif loc.table == "states" and loc.row is not None and rows_x is not None and \
                0 <= loc.row < len(rows_x):
            px, py = rows_x[loc.row].as_py(), rows_y[loc.row].as_py()
            if px is not None and py is not None:
                out.append((f.code, sev, float(px), float(py)))
    return out


def robust_range(values: np.ndarray, lower: float = 0.5, upper: float = 99.5,
                 include: float | None = None) -> tuple[float, float, int]:
    """(lo, hi, outside): the ``lower``..``upper`` percentiles of the finite values (widened to
    ``include``, e.g. 0), and how many finite values lie outside: histograms are drawn over this
    range so that a few wild values do not squash the distribution into one bin."""
    v = values[np.isfinite(values)]
    if not len(v):
        return 0.0, 1.0, 0
    lo, hi = (float(x) for x in np.percentile(v, [lower, upper]))
    if include is not None:
        lo, hi = min(lo, include), max(hi, include)
    if hi <= lo:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi, int(((v < lo) | (v > hi)).sum())


def _per_class_hist(ax, values: np.ndarray, cls: np.ndarray, xlabel: str, unit: str, *,
                    include: float | None = None, bins: int = 60, nice: float | None = None,
                    floor: float | None = None) -> None:
    """Density histograms per class over the robust range of ``values``, the count of values
    outside it written in the corner; ``unit`` of the values (the density is per ``unit``).
    ``nice``: the range widened by 5 % and out to multiples of ``nice`` (not below ``floor``), so
    that the tails just beyond the percentiles stay in the plot instead of piling up in the end
    bins."""
    ok = np.isfinite(values)
    lo, hi, _ = robust_range(values, include=include)
    if nice:
        span = hi - lo
        lo = np.floor((lo - 0.05 * span) / nice) * nice
        hi = np.ceil((hi + 0.05 * span) / nice) * nice
        if floor is not None:
            lo = max(lo, floor)
    v = values[ok]
    outside = int(((v < lo) | (v > hi)).sum())
    edges = np.linspace(lo, hi, bins + 1)
    for c in sorted(set(cls[ok]), key=lambda c: (c == "unknown", c)):
        sel = ok & (cls == c)
        ax.hist(np.clip(values[sel], lo, hi), bins=edges, histtype="step", linewidth=1.4,
                color=CLASS_COLORS.get(c, _UNKNOWN_CLASS), density=True,
                label=f"{c} (n={int(sel.sum()):,})")
    ax.set_xlim(lo, hi)
    ax.set_ylabel(f"density [1/({unit})]")
    if not ok.any():
        _no_data(ax, f"no {xlabel.split(' [')[0]}: no finite value")
    else:
        ax.legend(fontsize=8)
        note = (f"{outside:,} of {int(ok.sum()):,} values outside [{lo:.3g}, {hi:.3g}], "
                "in the end bins" if outside else f"all {int(ok.sum()):,} values")
        xlabel = f"{xlabel}\n{note}"
    ax.set_xlabel(xlabel, fontsize=9)


def _no_data(ax, text: str) -> None:
    """Say in the middle of an empty plot why it is empty."""
    ax.text(0.5, 0.5, text, transform=ax.transAxes, ha="center", va="center", fontsize=10,
            color="#444444", wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])


def speed_histogram(rec) -> Figure:
    """Distribution of speed over ground (from vx, vy) per class in km/h (what traffic engineers
    read), over the robust range of the speeds themselves: a motorway's 80-160 km/h fill the
    axis instead of its right half."""
    fig = _figure((6, 4))
    ax = fig.subplots()
    st = _states(rec)
    if st is not None:
        v = np.hypot(st["vx"], st["vy"]) * 3.6
        _per_class_hist(ax, v, _classes(rec, st["participant_id"]), "speed [km/h]", "km/h",
                        nice=5.0, floor=0.0)
    else:
        _no_data(ax, "no states with x, y, vx, vy")
    ax.set_title("Speed per class")
    return fig


def longitudinal_acceleration(st: dict[str, np.ndarray], window: float = 0.5
                              ) -> tuple[np.ndarray, np.ndarray]:
    """(sample index, signed longitudinal acceleration): the change of speed over ``window`` s
    of the same participant divided by the time it took (the baseline of the kinematics rules,
    so that measurement noise cannot fake large values); negative = braking."""
    pid, t = st["participant_id"], st["time"]
    if len(t) < 2:
        return np.zeros(0, np.int64), np.zeros(0)
    seg = np.r_[0, np.cumsum(np.diff(pid) != 0)]
    span = float(np.nanmax(t) - np.nanmin(t)) + 2 * window + 1
    key = seg * span + (t - np.nanmin(t))
    j = np.searchsorted(key, key + window)
    ok = j < len(t)
    jj = np.minimum(j, len(t) - 1)
    ok &= seg[jj] == seg
    i = np.flatnonzero(ok)
    jj = jj[i]
    speed = np.hypot(st["vx"], st["vy"])
    return i, (speed[jj] - speed[i]) / (t[jj] - t[i])


def acceleration_histogram(rec, window: float = 0.5) -> Figure:
    """Distribution of the signed longitudinal acceleration (:func:`longitudinal_acceleration`)
    per class, braking left of zero, accelerating right of it."""
    fig = _figure((6, 4))
    ax = fig.subplots()
    st = _states(rec)
    if st is not None:
        i, a = longitudinal_acceleration(st, window)
        if len(a):
            _per_class_hist(ax, a, _classes(rec, st["participant_id"][i]),
                            f"longitudinal acceleration over {window:g} s [m/s²]", "m/s²",
                            include=0.0)
            ax.axvline(0.0, color="#444444", linewidth=0.8, linestyle=":")
            for x, text, ha in ((0.02, "← braking", "left"), (0.98, "accelerating →", "right")):
                ax.text(x, 0.97, text, transform=ax.transAxes, ha=ha, va="top", fontsize=8,
                        color="#444444")
        else:
            _no_data(ax, f"no participant has two samples {window:g} s or more apart")
    else:
        _no_data(ax, "no states with x, y, vx, vy")
    ax.set_title("Longitudinal acceleration per class")
    return fig


def sample_rate_figure(rec, bin_s: float = 1.0) -> Figure:
    """Mean sample rate per participant present, per time bin, against nominal_rate_hz."""
    fig = _figure((8, 3.5))
    ax = fig.subplots()
    st = _states(rec)
    if st is not None:
        t = st["time"]
        ok = np.isfinite(t)
        b = np.floor(t[ok] / bin_s).astype(np.int64)
        b -= b.min() if len(b) else 0
        samples = np.bincount(b)
        # participants present per bin: distinct (bin, participant) pairs, ids compared as int64
        pid = st["participant_id"][ok]
        o = np.lexsort((pid, b))
        bs, ps = b[o], pid[o]
        first = np.r_[True, (bs[1:] != bs[:-1]) | (ps[1:] != ps[:-1])] if len(bs) else \
            np.zeros(0, bool)
        present = np.bincount(bs[first], minlength=len(samples))
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
    rec = open_recording(path, tables=["participants", "states", "unobserved"],
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
