"""The default scenario of ``aveas-format fit``: the simulation a recording describes (issue 42) —
its demand per class, the period of that demand, desired speeds, section and lanes — checked on a
recording with known truth (vehicles entering a straight 1 km, 3-lane road at known times and
constant speeds; no SUMO needed)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from aveas_format.fit.recorded import recorded_scenario
from aveas_format.mapref.build import build_recording
from aveas_format.sim.scenario import Scenario
from helpers_common import STRAIGHT_MAP


def _traffic(n_car: int, n_truck: int, period: float, drain: float, seed: int = 4):
    """Cars and trucks entering at s = 0 uniformly over ``period`` s, at constant speeds, sampled
    at 2 Hz while on the 1,000 m road, the recording lasting ``period + drain`` s."""
    rng = np.random.default_rng(seed)
    n = n_car + n_truck
    cls = np.array(["car"] * n_car + ["truck"] * n_truck)
    depart = np.sort(rng.uniform(0, period, n))[rng.permutation(n)]
    v = np.where(cls == "car", rng.normal(36.0, 4.0, n), rng.normal(24.0, 1.5, n))  # m/s
    lane = np.where(cls == "truck", rng.integers(1, 3, n), rng.integers(1, 4, n))
    pid, t, x, y, vx = [], [], [], [], []
    for i in range(n):
        ti = np.arange(np.ceil(depart[i] * 2) / 2, period + drain, 0.5)
        xi = v[i] * (ti - depart[i])
        keep = xi <= 999.0
        pid.append(np.full(keep.sum(), i)); t.append(ti[keep]); x.append(xi[keep])
        y.append(np.full(keep.sum(), -(lane[i] - 0.5) * 3.5)); vx.append(np.full(keep.sum(), v[i]))
    states = {"participant_id": np.concatenate(pid), "time": np.concatenate(t),
              "x": np.concatenate(x), "y": np.concatenate(y), "vx": np.concatenate(vx)}
    states["vy"] = np.zeros_like(states["x"])
    states["heading"] = np.zeros_like(states["x"])
    parts = {"participant_id": np.arange(n), "class": cls, "length": np.where(cls == "car", 4.5, 16.0),
             "width": np.where(cls == "car", 1.8, 2.5)}
    rec = build_recording(map_source=STRAIGHT_MAP, participants=parts, states=states,
                          duration_s=period + drain, partner="test", license="CC0-1.0")
    return rec, v * 3.6, cls


def test_the_scenario_follows_the_recording():
    # 150 cars and 30 trucks in 10 min (900 and 180 per hour), recorded for 5 min more
    rec, v_kmh, cls = _traffic(150, 30, period=600.0, drain=300.0)
    rs = recorded_scenario([rec])
    sc = rs.scenario
    assert rs.counted == {"car": 150, "truck": 30}  # every vehicle crosses the middle once
    assert rs.duration_s == pytest.approx(600.0, rel=0.03)  # the demand's period, not the 900 s
    assert sc.duration == rs.duration_s
    assert sc.cls("car").flow == pytest.approx(900.0, rel=0.03)
    assert sc.cls("truck").flow == pytest.approx(180.0, rel=0.03)
    # desired speeds: the recorded mean speeds' moments (constant speeds here: the speeds themselves)
    assert sc.cls("car").speed_mean_kmh == pytest.approx(v_kmh[cls == "car"].mean(), rel=1e-6)
    assert sc.cls("car").speed_std_kmh == pytest.approx(v_kmh[cls == "car"].std(ddof=1), rel=1e-6)
    assert sc.cls("truck").speed_mean_kmh == pytest.approx(v_kmh[cls == "truck"].mean(), rel=1e-6)
    assert sc.network.length == pytest.approx(999.0, abs=40.0) and sc.network.lanes == 3
    assert sc.lane_change_duration == 0.0  # the mean-speed metric
    assert sc.network.inflow == Scenario().network.inflow  # the rest: the base scenario's
    assert re.search(r"6\d\d s of demand, \d{3} cars/h, 1\d\d trucks/h, a 9\d\d m section with 3 "
                     r"lanes, lane changes instantaneous", rs.describe()), rs.describe()


def test_a_section_and_the_metric_shape_it():
    rec, _, _ = _traffic(60, 0, period=300.0, drain=60.0)
    rs = recorded_scenario([rec], classes=("car", "truck"), metric="time_headway", s_range=(200.0, 700.0))
    sc = rs.scenario
    assert [c.name for c in sc.classes] == ["car"]  # no trucks recorded: none simulated
    assert sc.network.length == 500.0
    assert sc.lane_change_duration == Scenario().lane_change_duration  # car-following: the base's
    assert sc.cls("car").flow == pytest.approx(720.0, rel=0.05)
