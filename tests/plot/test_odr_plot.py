"""Drawing maps (aveas_format.plot.map)."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.figure import Figure
from helpers_opendrive import fixture_map, real_map

from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import curved_highway
from aveas_format.plot.map import LANE_COLORS, plot_map, save_map


def test_plot_into_given_axes_colours_lanes_by_type():
    net = fixture_map("geometry_types.xodr")
    fig = Figure()
    ax = fig.add_subplot()
    assert plot_map(net, ax=ax) is ax
    polys = [c for c in ax.collections if type(c) is PolyCollection]  # (a Quiver is one too)
    assert len(polys) == 1 and len(polys[0].get_paths()) == len(net.lane_polygons())
    faces = {tuple(np.round(f, 3)) for f in polys[0].get_facecolors()}
    assert tuple(np.round(matplotlib.colors.to_rgba(LANE_COLORS["driving"]), 3)) in faces
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "driving" in legend
    labels = {t.get_text() for t in ax.texts}
    assert {"line", "arc", "border"} <= labels  # road ids of the fixture
    assert any(isinstance(c, LineCollection) for c in ax.collections)  # reference lines
    x0, y0, x1, y1 = net.bounds
    xl, yl = ax.get_xlim(), ax.get_ylim()
    assert xl[0] <= x0 and xl[1] >= x1 and yl[0] <= y0 and yl[1] >= y1


def test_save_map_is_headless_and_leaves_the_backend_alone(tmp_path):
    backend = matplotlib.get_backend()
    net = load_map(curved_highway(length=300.0, radius=150.0, lanes_left=1, lanes_right=2))
    p = save_map(net, tmp_path / "hw.png", dpi=60, labels=False, legend=False, title="")
    assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    svg = save_map(net, tmp_path / "hw.svg", dpi=60)
    assert b"<svg" in svg.read_bytes()[:400]
    assert matplotlib.get_backend() == backend


@pytest.mark.realdata
def test_junctions_are_outlined_and_labelled():
    net = real_map("esmini__fabriksgatan.xodr")
    ax = plot_map(net)
    texts = {t.get_text() for t in ax.texts}
    assert {f"J{j}" for j in net.junctions} <= texts
    dashed = [c for c in ax.collections if isinstance(c, LineCollection) and c.get_linestyle()[0][1] is not None]
    assert dashed, "no dashed junction outline"
    # junction roads are not labelled unless asked
    jroads = {rid for rid, r in net.roads.items() if r.junction is not None}
    assert not (jroads & texts)
    ax2 = plot_map(net, junction_road_labels=True, legend=False)
    assert jroads <= {t.get_text() for t in ax2.texts}
