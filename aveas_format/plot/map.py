"""Draw an OpenDRIVE map with matplotlib: lanes filled by type, reference lines, road ids, junctions.

>>> from aveas_format.opendrive import load_map
>>> from aveas_format.plot.map import plot_map, save_map
>>> net = load_map("Town04.xodr")                        # doctest: +SKIP
>>> ax = plot_map(net)                                  # doctest: +SKIP  (a new figure)
>>> plot_map(net, ax=my_ax, labels=False)               # doctest: +SKIP  (into your axes)
>>> save_map(net, "map.png")                            # doctest: +SKIP

No pyplot state is touched: without ``ax`` a standalone :class:`matplotlib.figure.Figure` (Agg
canvas) is made, so this works headless and does not change the backend of an interactive shell or notebook.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aveas_format.errors import require
from aveas_format.safeio import save_figure_atomic

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

    from aveas_format.opendrive.network import RoadNetwork

#: face colours of lanes by OpenDRIVE lane type (others: ``LANE_COLORS["other"]``). Lanes where
#: traffic joins are greens (entry, onRamp, mwyEntry), where it leaves oranges (exit, offRamp,
#: mwyExit), ramps between roads blues; driving is grey, bidirectional a muted purple.
LANE_COLORS: dict[str, str] = {
    "driving": "#8c8c8c",
    "bidirectional": "#8a78b0",
    "entry": "#4e9a5b",
    "onRamp": "#8cc084",
    "mwyEntry": "#2f6e3b",
    "exit": "#d9792b",
    "offRamp": "#f2b36f",
    "mwyExit": "#a65513",
    "connectingRamp": "#4f8fc0",
    "slipLane": "#74c0c8",
    "shoulder": "#c9c3a5",
    "border": "#b5b09a",
    "stop": "#c9c3a5",
    "restricted": "#d9a5a5",
    "parking": "#9fb8d9",
    "median": "#9fcf8f",
    "curb": "#cfcfcf",
    "sidewalk": "#e8d9b5",
    "walking": "#e8d9b5",
    "biking": "#d9b5d9",
    "bus": "#e0b070",
    "taxi": "#e0b070",
    "HOV": "#e0b070",
    "tram": "#b0a0e0",
    "rail": "#b0a0e0",
    "roadWorks": "#f0a040",
    "none": "#e6e6e6",
    "other": "#d0d0d0",
}


def _towards_white(color: str, amount: float) -> str:
    """``#rrggbb`` moved ``amount`` (0..1) of the way to white."""
    rgb = [int(color[i:i + 2], 16) for i in (1, 3, 5)]
    return "#" + "".join(f"{round(c + (255 - c) * amount):02x}" for c in rgb)


#: :data:`LANE_COLORS` lightened, for a map underneath other data (the recording figures)
BACKGROUND_LANE_COLORS: dict[str, str] = {t: _towards_white(c, 0.7) for t, c in LANE_COLORS.items()}


def _lane_type(net: RoadNetwork, road_id: str, section: int, lane_id: int) -> str:
    lane = net.roads[road_id].lane_sections[section].lane(lane_id)
    return lane.type if lane is not None else "none"


def plot_map(
    net: RoadNetwork,
    ax: Axes | None = None,
    *,
    step: float = 1.0,
    lane_colors: Mapping[str, str] | None = None,
    lane_edges: tuple[str, float] = ("#ffffff", 0.15),
    reference_lines: bool = True,
    labels: bool = True,
    junction_road_labels: bool = False,
    junctions: bool = True,
    legend: bool = True,
    title: str | None = None,
    figsize: tuple[float, float] | None = None,
) -> Axes:
    """Draw ``net`` into ``ax`` (a new figure when None) and return the axes.

    Lanes are filled by type (``lane_colors`` overrides :data:`LANE_COLORS`) and outlined
    (``lane_edges``: colour, line width in points), reference lines
    drawn thin with an arrow at their end (the direction of s), road ids written at the middle of
    each road (junction roads only with ``junction_road_labels``), junction areas outlined (dashed)
    with their ids. ``step``: sampling of lane borders and reference lines in metres.
    """
    import shapely

    require("matplotlib", extra="plot", what="figures")
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.patches import Patch

    colors = dict(LANE_COLORS)
    colors.update(lane_colors or {})
    if ax is None:
        from matplotlib.figure import Figure

        if figsize is None:
            x0, y0, x1, y1 = net.bounds
            aspect = (y1 - y0) / max(x1 - x0, 1e-9)
            figsize = (10.0, float(np.clip(10.0 * aspect, 3.0, 14.0)))
        fig = Figure(figsize=figsize)
        ax = fig.add_subplot()
    polys = net.lane_polygons(step=step)
    verts, faces, present = [], [], {}
    by_junction: dict[str, list[Any]] = {}
    for road_id, sec, lane_id, poly in polys:
        typ = _lane_type(net, road_id, sec, lane_id)
        color = colors.get(typ, colors["other"])
        present[typ if typ in colors else "other"] = color
        verts.append(np.asarray(poly.exterior.coords))
        faces.append(color)
        jid = net.roads[road_id].junction
        if jid is not None:
            by_junction.setdefault(jid, []).append(poly)
    ax.add_collection(PolyCollection(verts, facecolors=faces, edgecolors=lane_edges[0],
                                     linewidths=lane_edges[1], zorder=1))
    if reference_lines or labels:
        segs, mids = [], []
        for rid, road in net.roads.items():
            n = max(2, int(np.ceil(road.length / step)) + 1)
            x, y, h, _ = net.reference_line(rid, np.linspace(0.0, road.length, n))
            segs.append(np.column_stack([x, y]))
            m = n // 2
            mids.append((rid, road.junction is not None, x[m], y[m], h[m]))
        if reference_lines:
            ax.add_collection(LineCollection(segs, colors="#303030", linewidths=0.4, zorder=2))
            ends = np.array([[s[-2, 0], s[-2, 1], s[-1, 0] - s[-2, 0], s[-1, 1] - s[-2, 1]] for s in segs if len(s) > 1])
            if len(ends):
                d = np.hypot(ends[:, 2], ends[:, 3])
                d[d == 0] = 1.0
                ax.quiver(ends[:, 0], ends[:, 1], ends[:, 2] / d, ends[:, 3] / d, color="#303030",
                          angles="xy", scale_units="dots", scale=1 / 6, width=0.002, zorder=2)
        if labels:
            for rid, in_j, x, y, _ in mids:
                if in_j and not junction_road_labels:
                    continue
                ax.annotate(rid, (x, y), fontsize=6, color="#0b3d91", ha="center", va="center",
                            zorder=4, bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none",
                                            "alpha": 0.7})
    if junctions and by_junction:
        jsegs = []
        for jid, plist in by_junction.items():
            area = shapely.union_all(shapely.make_valid(np.array(plist, dtype=object)).tolist(), grid_size=None)
            area = area.buffer(0.05)
            geoms = getattr(area, "geoms", [area])
            for g in geoms:
                if g.geom_type == "Polygon" and not g.is_empty:
                    jsegs.append(np.asarray(g.exterior.coords))
            if labels:
                c = area.representative_point()
                ax.annotate(f"J{jid}", (c.x, c.y), fontsize=7, color="#b22222", ha="center",
                            va="center", zorder=5, fontweight="bold")
        ax.add_collection(LineCollection(jsegs, colors="#b22222", linewidths=0.8, linestyles="--", zorder=3))
    x0, y0, x1, y1 = net.bounds
    ax.update_datalim([(x0, y0), (x1, y1)])
    ax.margins(0.02)
    ax.autoscale_view()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if title is None:
        name = Path(net.path).name if net.path else (net.header.name or "OpenDRIVE map")
        title = f"{name}: {len(net.roads)} roads, {len(net.junctions)} junctions"
    if title:
        ax.set_title(title, fontsize=10)
    if legend and present:
        handles = [Patch(facecolor=c, edgecolor="#999999", label=t) for t, c in sorted(present.items())]
        if junctions and by_junction:
            from matplotlib.lines import Line2D

            handles.append(Line2D([], [], color="#b22222", linestyle="--", label="junction"))
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.85)
    return ax


def save_map(net: RoadNetwork, path: str | Path, *, dpi: int = 150, **kw: Any) -> Path:
    """Draw ``net`` with :func:`plot_map` (keywords as there) and write it to ``path`` (PNG, SVG or
    PDF by the suffix)."""
    ax = plot_map(net, **kw)
    fig = ax.figure
    fig.tight_layout()
    return save_figure_atomic(fig, path, dpi=dpi)


__all__ = ["BACKGROUND_LANE_COLORS", "LANE_COLORS", "plot_map", "save_map"]
