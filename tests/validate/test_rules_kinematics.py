"""Kinematics rules: position jumps told along vs across the motion, instantaneous lane changes
(one finding per vehicle, not dozens of jumps), and exact (simulated) values at a class limit."""

from __future__ import annotations

import numpy as np

import aveas_format
import helpers_validate as vf


def _messages(rec, code):
    rep = aveas_format.validate(rec, select=[code])
    return [f.message for f in rep.findings() if f.code == code]


def test_position_jump_tells_along_from_across():
    sc = vf.fresh()
    sc["tracks"][0]["x"][75:] += 3.0  # forward
    (msg,) = _messages(vf.build(sc), "kinematics.position_jump")
    assert "off by 3.0 m (3.0 m along its motion, 0.0 m across" in msg
    sc = vf.fresh()
    sc["std"] = {k: 0.0 for k in sc["std"]}  # exact: tolerance 1 m
    sc["tracks"][0]["y"][75:] -= 1.2  # sideways, within its lane: no lane change
    (msg,) = _messages(vf.build(sc), "kinematics.position_jump")
    assert "off by 1.2 m (0.0 m along its motion, 1.2 m across" in msg


def test_instant_lane_changes_one_finding_per_vehicle():
    """Three lane changes of one car without lateral motion: one instant_lane_change finding that
    counts them, and no position_jump; a smooth lane change (lateral velocity) is neither."""
    sc = vf.fresh()
    y = sc["tracks"][0]["y"]
    y[40:] -= 3.5
    y[80:] += 3.5
    y[120:] -= 3.5
    rec = vf.build(sc)
    rep = aveas_format.validate(rec, select=["kinematics"])
    assert rep.codes() == {"kinematics.instant_lane_change"}
    (f,) = rep.findings()
    assert "changes lane instantaneously 3 time(s), first at 1.6 s: it jumps up to 3.5 m" in f.message
    assert "--lanechange.duration" in f.message and "lane_change_duration" in f.message
    sc = vf.fresh()
    tr = sc["tracks"][0]
    t = tr["time"]
    s = np.clip((t - 1.0) / 3.0, 0, 1)
    prof = s ** 3 * (10 - 15 * s + 6 * s * s)
    tr["y"] = tr["y"] - 3.5 * prof
    tr["vy"] = -3.5 * 30 * s ** 2 * (1 - s) ** 2 / 3.0
    tr["heading"] = np.arctan2(tr["vy"], tr["vx"])
    assert aveas_format.validate(vf.build(sc), select=["kinematics"]).codes() == set()


def test_exact_values_at_a_limit_and_their_digits():
    """A simulated bus (std 0) at 40.0003 m/s passes the bus's 40 m/s (relative tolerance 1e-4 for
    exact values); at 40.02 m/s it is reported with the digits that show the excess."""
    def bus_at(v):
        sc = vf.fresh()
        sc["participants"]["class"][3] = "bus"
        sc["participants"]["class_pmf"][3] = np.eye(13)[2]
        sc["participants"]["length"][3] = 12.0
        sc["participants"]["width"][3] = 2.5
        sc["tracks"][3] = vf.track(150.0, -3, v)
        sc["std"] = {k: 0.0 for k in sc["std"]}
        return vf.build(sc)

    assert _messages(bus_at(40.0003), "kinematics.speed") == []
    (msg,) = _messages(bus_at(40.0049), "kinematics.speed")
    assert "moves at 40.005 m/s" in msg and "above the 40.0 m/s plausible" in msg


def test_distinct_digits():
    from aveas_format.validate.rules.kinematics import distinct_digits

    assert distinct_digits(np.array([40.0003, 41.23456, 12.0]), np.array([40.0, 40.0, 12.0])).tolist() \
        == [40.0003, 41.235, 12.0]
