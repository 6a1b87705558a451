"""build_recording and its helpers: defaults filled from plain arrays, georeferencing, referencing."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import aveas_format
from aveas_format.crs import LocalFrame
from aveas_format.mapref.build import heading_from_velocity, velocity_from_positions
from aveas_format.numeric import wrap_angle

from helpers_common import STRAIGHT_MAP


def test_readme_example(tmp_path):
    rec = aveas_format.build_recording(
        map_source=str(STRAIGHT_MAP), partner="KIT", method="aerial",
        participants={"participant_id": [0], "class": ["car"], "length": [4.5], "width": [1.8]},
        states={"participant_id": [0, 0], "time": [0.0, 0.04], "x": [10.0, 11.2],
                "y": [-1.75, -1.75]})
    s = rec.states
    assert s.column("vx").to_pylist() == pytest.approx([30.0, 30.0])
    assert s.column("heading").to_pylist() == [0.0, 0.0]
    assert s.column("road_id").to_pylist() == ["1", "1"]
    assert s.column("lane_id").to_pylist() == [-1, -1]
    assert s.column("road_s").to_pylist() == pytest.approx([10.0, 11.2])
    assert rec.participants.column("role").to_pylist() == ["observed"]
    assert rec.participants.column("provenance").to_pylist() == ["natural"]
    assert rec.meta.nominal_rate_hz == pytest.approx(25.0)
    assert rec.meta.crs.startswith("+proj=tmerc +lat_0=48.9")
    path = rec.write(tmp_path / "readme.aveas")
    assert aveas_format.validate(path).counts["error"] == 0


def test_lon_lat_are_consistent_with_the_crs(rec):
    s = rec.states
    x, y = LocalFrame.of(rec).from_wgs84(s.column("lon").to_numpy(), s.column("lat").to_numpy())
    assert np.abs(x - s.column("x").to_numpy()).max() < 1e-6
    assert np.abs(y - s.column("y").to_numpy()).max() < 1e-6


def test_off_map_samples_have_null_road_coordinates():
    rec = aveas_format.build_recording(
        map_source=STRAIGHT_MAP, participants={"participant_id": [0], "class": ["pedestrian"],
                                               "length": [0.5], "width": [0.5]},
        states={"participant_id": [0, 0, 0], "time": [0.0, 1.0, 2.0], "x": [10.0, 10.0, 10.0],
                "y": [-1.0, 40.0, 80.0]})
    s = rec.states
    assert s.column("road_id").to_pylist() == ["1", None, None]
    assert s.column("lane_id").null_count == 2 and s.column("road_s").null_count == 2


def test_missing_required_inputs_are_named():
    with pytest.raises(aveas_format.FormatError, match="participants: column 'length' is required"):
        aveas_format.build_recording(map_source=STRAIGHT_MAP,
                                     participants={"participant_id": [0], "class": ["car"],
                                                   "width": [2.0]},
                                     states={"participant_id": [0], "time": [0.0], "x": [0.0],
                                             "y": [0.0]})


def test_simulated_recordings_get_simulated_roles(rec):
    sim = aveas_format.build_recording(
        map_source=STRAIGHT_MAP, method="traffic_simulation",
        participants={"participant_id": [0], "class": ["car"], "length": [4.5], "width": [1.8]},
        states={"participant_id": [0], "time": [0.0], "x": [1.0], "y": [-1.75]})
    assert sim.meta.provenance.value == "simulated"
    assert sim.participants.column("role").to_pylist() == ["simulated_agent"]


def test_velocity_from_positions_per_participant():
    pid = np.array([0, 0, 0, 1, 1])
    t = np.array([0.0, 1.0, 2.0, 0.0, 0.5])
    x = np.array([0.0, 2.0, 6.0, 100.0, 101.0])
    y = np.zeros(5)
    vx, vy = velocity_from_positions(pid, t, x, y)
    assert vx.tolist() == [2.0, 3.0, 4.0, 2.0, 2.0]  # one-sided at the ends, never across ids
    assert vy.tolist() == [0.0] * 5


def test_heading_is_held_while_standing():
    pid = np.array([0, 0, 0, 0, 1, 1])
    vx = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])
    vy = np.array([0.0, 1.0, 0.1, 0.0, 0.0, -2.0])
    h = heading_from_velocity(pid, vx, vy)
    assert h[:4] == pytest.approx([np.pi / 4] * 4)  # back-filled, then held
    assert h[4:] == pytest.approx([-np.pi / 2] * 2)  # not taken from participant 0


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4))
def test_wrap_angle(a):
    w = float(wrap_angle(np.array([a]))[0])
    assert -np.pi < w <= np.pi
    assert np.isclose(np.cos(w), np.cos(a), atol=1e-9) and np.isclose(np.sin(w), np.sin(a), atol=1e-9)
