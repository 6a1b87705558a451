"""Every map the package writes passes ASAM qc-opendrive 1.0.0: all its checks that apply to
OpenDRIVE 1.8 run (22 of 23: one is for <= 1.7 only) and find 0 issues. The checker runs in its
own environment (its pins clash with ours), created on first use; without it the tests skip."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_common import shared
from helpers_lanelet2 import ORIGIN, crossroads
from helpers_opendrive import qc_opendrive

from aveas_format.opendrive import fit_road, load_map
from aveas_format.opendrive.builder import curved_highway, straight_highway


def _qc(tmp_path, name: str, text: str) -> dict:
    p = tmp_path / f"{name}.xodr"
    p.write_text(text)
    res = qc_opendrive(p)
    assert res["errors"] == [], res["errors"]
    assert res["issues"] == [], res["issues"][:5]
    assert len(res["applicable"]) >= 20, res["skipped"]
    return res


def _fitted() -> str:
    truth = load_map(curved_highway(length=500.0, radius=250.0, straight=100.0, spiral=60.0, lanes_right=3))
    s = np.linspace(0.0, 500.0, 200)
    lines = [np.column_stack(truth.road_to_world("1", s, np.full(len(s), t))[:2]) for t in (-1.75, -5.25, -8.75)]
    return fit_road(lines).xodr


def _maps():
    from aveas_format.converters.levelx import highd_map
    from aveas_format.sample import SITE_CRS

    return {
        "straight_both_ways": lambda: straight_highway(lanes_left=2, geo_reference="+proj=tmerc +lat_0=49 +lon_0=8"),
        "curved": lambda: curved_highway(radius=300.0, spiral=40.0, straight=10.0, lanes_left=2),
        # the demo's (sample.highway_scene) and the SUMO runner's (sim.runner) maps
        "demo": lambda: straight_highway(length=1000.0, lanes_right=3, geo_reference=SITE_CRS),
        "sumo_runner": lambda: straight_highway(length=1500.0, lanes_right=3, lane_width=3.5, name="sim_highway"),
        "roadfit": _fitted,
        "highd": lambda: highd_map(np.array([8.5, 12.3, 16.0]), np.array([21.0, 24.8, 28.6]), 0.0, 400.0),
        "lanelet2_crossroads": lambda: __import__("aveas_format.opendrive.lanelet2", fromlist=["x"])
        .lanelet2_to_opendrive(crossroads()[0], origin=ORIGIN).xodr,
    }


@pytest.mark.parametrize("name", sorted(_maps()))
def test_written_maps_pass_qc_opendrive(tmp_path, name):
    _qc(tmp_path, name, _maps()[name]())


def test_maps_built_from_trajectories_pass_qc_opendrive(tmp_path):
    from helpers_mapbuild import highd_like, sumo_scene

    from aveas_format.opendrive.roadfit.tracks import map_from_tracks

    d = highd_like(300, duration=300, seed=2)
    _qc(tmp_path, "built_highd", map_from_tracks(d["x"], d["y"], d["track"], d["time"], heading=d["heading"]).xodr)
    sc = sumo_scene(tmp_path / "sumo_scene" if (tmp_path / "sumo_scene").mkdir() is None else tmp_path)
    _qc(tmp_path, "built_sumo", map_from_tracks(sc.x, sc.y, sc.track, sc.time, heading=sc.heading).xodr)


@pytest.mark.realdata
@pytest.mark.parametrize("osm,origin,kind", [("lanelet2__mapping_example.osm", (49.0, 8.4), "tmerc"),
                                             ("interaction__TestScenarioForScripts.osm", (0.0, 0.0), "utm")])
def test_converted_public_lanelet2_maps_pass_qc_opendrive(tmp_path, osm, origin, kind):
    from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive

    conv = lanelet2_to_opendrive(shared("data", "real", "lanelet2", osm), origin=origin, projection_kind=kind)
    _qc(tmp_path, osm, conv.xodr)
