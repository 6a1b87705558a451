"""Every analytic case of ../shared/data/criticality/vectors.json, reproduced by building a small
recording with the given motion and running ``derive`` on it. The motions are exact (noise-free
positions and velocities that declare a std), so the pairs are derived from the states' own
values (``velocities="states"``): the cases check the definitions, the smoothing has its own
accuracy tests (test_kinematics, test_velocities, test_near_miss)."""

from __future__ import annotations

import numpy as np
import pytest
import shapely

from aveas_format.derive import derive
from aveas_format.derive.interactions import ttc_boxes

from helpers_derive import recording, road_map, row, value, vectors

LANE_Y = -1.75  # centre of lane -1 of the test map


def _following(gap, v_f, v_l, L=4.5, a_f=0.0, a_l=0.0, rotate=0.0, shift=(0.0, 0.0)):
    f_front = 100.0
    return recording([
        {"x": f_front - L / 2, "y": LANE_Y, "length": L, "width": 1.8, "vx": v_f, "vy": 0.0,
         "ax": a_f},
        {"x": f_front + gap + L / 2, "y": LANE_Y, "length": L, "width": 1.8, "vx": v_l, "vy": 0.0,
         "ax": a_l},
    ], rotate=rotate, shift=shift)


def _at0(rec, relation="leader", pid=0):
    it = rec.derived["interactions"]
    r = row(it, participant_id=pid, time=0.0, relation=relation)
    assert len(r) == 1, r
    return r[0]


@pytest.mark.realdata
@pytest.mark.parametrize("rotate", [0.0, np.pi / 6, np.pi / 4])
def test_ttc1d_cv(rotate):
    v = vectors()["ttc1d_cv"]
    for var in v["variants"]:
        i = var["inputs"]
        rec = _following(i["gap_m"], i["v_follower"], i["v_leader"], rotate=rotate,
                         shift=(30.0, -20.0))
        derive(rec, only="interactions", box_2d=False, velocities="states")
        r = _at0(rec)
        want = value(var["expected"]["ttc_s"])
        got = np.inf if r["ttc"] is None else r["ttc"]
        assert got == pytest.approx(want, abs=v["tolerance_abs"]), var["id"]
        if np.isfinite(want):
            assert r["ttc_kind"] == "lane_1d"
            assert r["ttc_std"] > 0
        # the follower's row mirrors the leader's
        assert _at0(rec, "follower", pid=1)["ttc"] == r["ttc"]


@pytest.mark.realdata
def test_ttc1d_ca_leader_braking():
    v = vectors()["ttc1d_ca_leader_braking"]
    i = v["inputs"]
    rec = _following(i["gap_m"], i["v_follower"], i["v_leader"], a_f=i["a_follower"],
                     a_l=i["a_leader"])
    derive(rec, only="interactions", velocities="states")
    r = _at0(rec)
    assert r["ttc_ca"] == pytest.approx(v["expected"]["ttc_s"], abs=v["tolerance_abs"])
    assert r["ttc"] is None  # equal speeds: no collision course at constant velocity
    assert r["ttc_ca_std"] > 0


@pytest.mark.realdata
def test_headway_thw_dhw():
    v = vectors()["headway_thw_dhw"]
    i, e = v["inputs"], v["expected"]
    gap = i["leader_rear_s"] - i["follower_front_s"]
    rec = _following(gap, i["v_follower"], i["v_leader"], L=i["leader_length"])
    derive(rec, only="interactions", box_2d=False, velocities="states")
    r = _at0(rec)
    tol = v["tolerance_abs"]
    assert r["gap"] == pytest.approx(e["gap_m"], abs=tol)
    assert r["dhw"] == pytest.approx(e["dhw_front_to_front_m"], abs=tol)
    assert r["thw"] == pytest.approx(e["thw_net_s"], abs=tol)
    assert r["dhw"] / i["v_follower"] == pytest.approx(e["thw_gross_s"], abs=tol)
    # a standing follower has infinite headway: null
    rec0 = _following(gap, 0.0, i["v_leader"], L=i["leader_length"])
    derive(rec0, only="interactions", box_2d=False, velocities="states")
    assert _at0(rec0)["thw"] is None and value(e["thw_if_v_follower_zero"]) == np.inf


def _box(a):
    return (a["x"], a["y"], a["heading_rad"], a["length"], a["width"], a["vx"], a["vy"])


@pytest.mark.realdata
@pytest.mark.parametrize("case", ["ttc2d_rear_end_aligned", "ttc2d_perpendicular_collision"])
def test_ttc2d(case):
    v = vectors()[case]
    A, B = v["inputs"]["A"], v["inputs"]["B"]
    want = value(v["expected"]["ttc_s"])
    assert float(ttc_boxes(*_box(A), *_box(B))) == pytest.approx(want, abs=v["tolerance_abs"])
    # through a recording: far off the road (no lane relation) -> a conflicting box_2d pair
    actors = [{"x": a["x"], "y": a["y"], "heading": a["heading_rad"], "length": a["length"],
               "width": a["width"], "vx": a["vx"], "vy": a["vy"]} for a in (A, B)]
    rec = recording(actors, shift=(0.0, 500.0), xodr=road_map())
    derive(rec, only="interactions", velocities="states")
    r = _at0(rec, "conflicting")
    assert r["other_id"] == 1 and r["ttc_kind"] == "box_2d"
    assert r["ttc"] == pytest.approx(want, abs=v["tolerance_abs"])
    assert r["ttc_std"] is not None and r["ttc_std"] >= 0


def _crossing(v, rotate=0.0, shift=(0.0, 500.0)):
    A, B = v["inputs"]["A"], v["inputs"]["B"]
    actors = [{"x": a["x"], "y": a["y"], "heading": a["heading_rad"], "length": a["length"],
               "width": a["width"], "vx": a["vx"], "vy": a["vy"]} for a in (A, B)]
    return recording(actors, duration=6.0, rotate=rotate, shift=shift, xodr=road_map())


def _area(v, rotate=0.0, shift=(0.0, 500.0)):
    ca = v["inputs"]["conflict_area"]
    box = shapely.box(ca["xmin"], ca["ymin"], ca["xmax"], ca["ymax"])
    box = shapely.affinity.rotate(box, rotate, origin=(0, 0), use_radians=True)
    return shapely.affinity.translate(box, *shift).wkt


@pytest.mark.realdata
@pytest.mark.parametrize("rotate", [0.0, 0.7])
def test_pet_crossing_explicit_area(rotate):
    v = vectors()["pet_crossing_lane_ca"]
    e = v["expected"]
    rec = _crossing(v, rotate=rotate)
    derive(rec, only=["interactions", "encroachments"], conflict_areas=[_area(v, rotate)],
           velocities="states")
    en = rec.derived["encroachments"].to_pylist()
    assert len(en) == 1
    r = en[0]
    tol = v["tolerance_abs"]
    assert (r["first_id"], r["second_id"]) == (0, 1)  # A first
    assert r["time_first_exit"] == pytest.approx(e["t_exit_A"], abs=tol)
    assert r["time_second_enter"] == pytest.approx(e["t_entry_B"], abs=tol)
    assert r["pet"] == pytest.approx(e["pet_s"], abs=tol)
    assert r["pet_std"] > 0
    # the boxes never touch: no conflicting row at t = 0
    assert not row(rec.derived["interactions"], participant_id=0, time=0.0,
                   relation="conflicting")


@pytest.mark.realdata
def test_pet_crossing_swept_paths():
    """Without an explicit area the conflict area is the overlap of the swept footprints: a 2 m
    square (B's width x A's width): A's rear leaves x = 1 at t = 1.9 s, B's front reaches y = -1 at
    t = 38.5/12.5 = 3.08 s, PET = 1.18 s."""
    v = vectors()["pet_crossing_lane_ca"]
    rec = _crossing(v)
    derive(rec, only="encroachments")
    r = rec.derived["encroachments"].to_pylist()[0]
    assert r["time_first_exit"] == pytest.approx(1.9, abs=1e-9)
    assert r["time_second_enter"] == pytest.approx(3.08, abs=1e-9)
    assert r["pet"] == pytest.approx(1.18, abs=1e-9)
    area = shapely.from_wkb(r["geometry"])
    assert area.area == pytest.approx(4.0, rel=1e-6)


def test_pet_undefined_when_both_inside():
    """Both occupy the area at once (a collision course): PET is null."""
    rec = recording([
        {"x": -20.0, "y": 0.0, "heading": 0.0, "length": 4.0, "width": 2.0, "vx": 10.0, "vy": 0.0},
        {"x": 0.0, "y": -15.0, "heading": np.pi / 2, "length": 4.0, "width": 2.0, "vx": 0.0,
         "vy": 10.0}], duration=5.0, shift=(0.0, 500.0), xodr=road_map())
    derive(rec, only="encroachments")
    r = rec.derived["encroachments"].to_pylist()[0]
    assert r["pet"] is None and r["time_second_enter"] <= r["time_first_exit"]


@pytest.mark.realdata
def test_edie_lane_segment():
    v = vectors()["edie_lane_segment"]
    e = v["expected"]
    seg = v["inputs"]["segment"]
    actors = [
        {"x": 30.0, "y": LANE_Y, "length": 4.5, "width": 1.8, "vx": 20.0, "vy": 0.0},
        {"x": 10.0, "y": LANE_Y, "length": 4.5, "width": 1.8, "vx": 10.0, "vy": 0.0},
        {"x": 2.0, "y": LANE_Y, "length": 4.5, "width": 1.8, "vx": 0.0, "vy": 0.0},
    ]
    rec = recording(actors, duration=seg["t1"])
    derive(rec, only="traffic", cell_length_m=seg["x1"] - seg["x0"],
           cell_duration_s=seg["t1"] - seg["t0"])
    r = row(rec.derived["traffic"], lane_id=-1, s_start=0.0, time_start=0.0)
    assert len(r) == 1
    r = r[0]
    tol = 1e-6  # exact clipping of the sampled (linear) trajectories
    assert r["flow"] == pytest.approx(e["flow_veh_per_h"], abs=tol)
    assert r["density"] == pytest.approx(e["density_veh_per_km"], abs=tol)
    assert r["mean_speed"] == pytest.approx(e["space_mean_speed_m_s"], abs=tol)
    assert r["count"] == 3


@pytest.mark.realdata
@pytest.mark.parametrize("method", ["ca_kalman_rts", "savitzky_golay"])
def test_accel_kinematics(method):
    v = vectors()["accel_kinematics"]
    rel = v["tolerance_rel"]
    for var in v["variants"]:
        i = var["inputs"]
        t = np.arange(i["n_samples"]) * i["dt"]
        if var["id"] == "a_circle_ccw":
            x, y = 100 * np.cos(0.2 * t), 100 * np.sin(0.2 * t)
        else:
            x, y = 25 * t - 1.5 * t * t, 0 * t
        from aveas_format.mapref.build import build_recording

        n = len(t)
        rec = build_recording(
            map_source=road_map(), method="aerial", partner="test",
            participants={"participant_id": [0], "class": ["car"], "length": [4.5],
                          "width": [1.8]},
            states={"participant_id": np.zeros(n, int), "time": t, "x": x, "y": y + 300,
                    "x_std": np.zeros(n), "y_std": np.zeros(n)})
        derive(rec, only="kinematics", method=method)
        k = rec.derived["kinematics"].slice(i["evaluate_at_sample"], 1).to_pylist()[0]
        for q, want in var["expected"].items():
            tol = max(rel * abs(want), 0.02 if q != "speed" else 0.1)
            assert k[q] == pytest.approx(want, abs=tol), (var["id"], q)
