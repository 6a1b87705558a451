"""Degenerate lane sections, geometries and lanes (issue 42 point 1): zero- and near-zero-length
sections (two ``<laneSection s="0">``, one of 1e-9 m, one at the road's end), geometries of length
0 and 1e-9, lanes of zero width, a road of length 0. tests/data/degenerate.xodr isolates each
case (its header comment says which road holds which); reader, lanes, polygons, projection,
check, ``map info/check/plot`` and map-referencing take them, against the truth the file states.
The same classes on the real maps under ../shared/data: tests/realdata/test_maps.py."""

from __future__ import annotations

import json

import numpy as np
import pytest
import shapely

from aveas_format.cli.app import app
from aveas_format.cli.common import run
from aveas_format.opendrive import load_map
from helpers_common import DATA

DEGENERATE = DATA / "degenerate.xodr"


@pytest.fixture(scope="module")
def net():
    return load_map(DEGENERATE)


def test_the_reader_keeps_every_section_and_geometry(net):
    assert [len(net.roads[r].lane_sections) for r in "12345"] == [2, 3, 1, 2, 1]
    assert [g.length for g in net.roads["3"].geometries] == [0.0, 1e-9, 0.0, 1e-9, 50.0]
    assert net.roads["5"].length == 0.0


def test_a_zero_length_section_applies_nowhere(net):
    # road 1: the second <laneSection s="0"> is in effect from s = 0 (its sidewalk -2, 3.5..5.5 m right)
    lane, off = net.lane_at(["1"] * 3, [0.0, 50.0, 100.0], [-4.5, -4.5, -4.5])
    assert lane.tolist() == [-2, -2, -2] and np.allclose(off, 0.0)
    # road 2: the section at s = 100 (= length; a 1 m sidewalk) never applies, even at s = 100
    lane, off = net.lane_at(["2"] * 4, [0.0, 1e-9, 99.99, 100.0], [2.0] * 4)
    assert lane.tolist() == [1] * 4 and np.allclose(off, 0.25)
    assert net.lane_type("2", 100.0, 1).tolist() == ["driving"]
    inner, outer = net.lane_borders("2", 100.0, 1)
    assert (inner[0], outer[0]) == (0.0, 3.5)


def test_zero_width_lanes_hold_no_point(net):
    # road 4, s < 30: lanes 1, -1 (width 0) and -2 (1e-12): nothing to be in; s >= 30: lane -1 3.5 m
    lane, _ = net.lane_at(["4"] * 4, [10.0, 10.0, 29.9, 40.0], [0.5, -0.5, 1e-3, -1.0])
    assert lane.tolist() == [0, 0, 0, -1]


def test_lane_counts_leave_out_zero_width_lanes_and_count_drivable_types(net):
    # road 1: driving + sidewalk on the right (the section in effect); road 4: lanes of zero width
    # up to s = 30 (none counts), then one of 3.5 m on the right (the left one has no <width>)
    c = net.lane_counts(["1", "1", "4", "4", "2"], [10.0, 90.0, 10.0, 40.0, 50.0])
    assert c["right"].tolist() == [2, 2, 0, 1, 0] and c["right_drivable"].tolist() == [1, 1, 0, 1, 0]
    assert c["left"].tolist() == [0, 0, 0, 0, 1] and c["left_drivable"].tolist() == [0, 0, 0, 0, 1]


def test_polygons_skip_what_has_no_area(net):
    polys = net.lane_polygons(step=5.0)
    got = {(r, sec, lane): p.area for r, sec, lane, p in polys}
    # no polygon for the zero-length sections (road 1 section 0, road 2 section 2, road 5) nor the
    # 1e-9 m section of road 2, nor lanes of zero width (road 4 section 0)
    assert set(got) == {("1", 1, -1), ("1", 1, -2), ("2", 1, 1), ("3", 0, -1), ("4", 1, -1)}
    assert got[("1", 1, -1)] == pytest.approx(350.0)
    assert got[("1", 1, -2)] == pytest.approx(200.0)
    assert got[("2", 1, 1)] == pytest.approx(350.0)
    assert got[("3", 0, -1)] == pytest.approx(175.0)
    assert got[("4", 1, -1)] == pytest.approx(105.0)
    assert all(shapely.is_valid(p) for *_, p in polys)


def test_world_to_road_on_degenerate_roads(net):
    road = ["1", "2", "3", "3", "3", "4"]
    s = np.array([50.0, 50.0, 1e-10, 1.5e-9, 25.0, 45.0])
    t = np.array([-4.0, 1.0, -1.0, -1.0, -1.0, -1.0])
    x, y, _, h = net.road_to_world(road, s, t)
    for proj in (net.world_to_road(x, y, h), net.world_to_road_track(x, y, h)):
        assert proj.road_id.tolist() == road
        assert proj.lane_id.tolist() == [-2, 1, -1, -1, -1, -1]
        # s within the 1e-7 m by which a foot point may pass its geometry's end (projection._S_TOL)
        assert np.allclose(proj.s, s, atol=1e-7) and np.allclose(proj.t, t, atol=1e-9)
    # on the zero-width lanes of road 4 and at the zero-length road 5: no road
    off = net.world_to_road(np.array([10.0, 0.0]), np.array([59.9, 79.0]))
    assert off.road_id.tolist() == [None, None]


def test_map_check_reports_each_degenerate_section_with_its_line(net):
    found = [(f.code, f.road_id, f.line) for f in net.check() if f.code in ("lane.section_length",
                                                                             "geometry.zero_length")]
    assert sorted(found, key=str) == sorted([
        ("lane.section_length", "1", 14),   # two <laneSection s="0">
        ("lane.section_length", "2", 30),   # 1e-9 m long
        ("lane.section_length", "2", 38),   # at the road's end
        ("lane.section_length", "5", 82),   # the road is 0 m long
        ("geometry.zero_length", "3", 46), ("geometry.zero_length", "3", 47),
        ("geometry.zero_length", "3", 48), ("geometry.zero_length", "3", 49),
        ("geometry.zero_length", "5", 79),
    ], key=str)
    assert not [f for f in net.check() if f.severity == "error"]
    msgs = {f.line: f.message for f in net.check()}
    assert "starts where the next one does" in msgs[14]
    assert "1e-09 m long" in msgs[30]
    assert "at or after the road's end" in msgs[38]


def test_map_commands_take_the_degenerate_map(tmp_path, capsys):
    assert run(app, ["map", "check", str(DEGENERATE), "--format", "json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["valid"] and report["counts"]["warning"] == 4
    assert run(app, ["map", "info", str(DEGENERATE), "--format", "json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["roads"] == 5 and info["lane_sections"] == 9
    # the lanes in effect: 100 m x (3.5 + 2) on road 1, 100 m x 3.5 on road 2, 50 m and 30 m x 3.5
    assert info["lane_length_m"]["driving"] == pytest.approx(100 + 100 + 50 + 60 + 30 + 30 + 30, abs=1e-6)
    out = tmp_path / "degenerate.png"
    assert run(app, ["map", "plot", str(DEGENERATE), "-o", str(out)]) == 0
    assert out.stat().st_size > 10_000
    assert "internal error" not in capsys.readouterr().err


def test_map_referencing_on_degenerate_roads():
    from aveas_format.mapref.build import build_recording

    net = load_map(DEGENERATE)
    tm = np.arange(0.0, 4.0, 0.5)
    s = 0.5 + 2.0 * tm  # from s = 0.5 through the 1e-9 m geometries' neighbourhood on road 3
    x, y, _, h = net.road_to_world(["3"] * len(tm), s, -1.75)
    rec = build_recording(
        map_source=DEGENERATE, crs="+proj=tmerc +lat_0=48 +lon_0=8 +ellps=WGS84 +units=m",
        participants={"participant_id": [1], "class": ["car"], "length": [4.5], "width": [1.8]},
        states={"participant_id": [1] * len(tm), "time": tm, "x": x, "y": y, "heading": h})
    st = rec.states
    assert st.column("road_id").to_pylist() == ["3"] * len(tm)
    assert st.column("lane_id").to_pylist() == [-1] * len(tm)
    assert np.allclose(st.column("road_s").to_numpy(), s, atol=1e-6)
