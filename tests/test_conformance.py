"""The independently written conformance recording is always read and validated without errors."""

from __future__ import annotations

import numpy as np

import aveas_format
from aveas_format.crs import LocalFrame


def test_conformance_recording_reads(conformance_path):
    rec = aveas_format.open(conformance_path)
    assert rec.meta.recording_id == "conformance-highway-1"
    assert rec.participants.num_rows == 30 and rec.states.num_rows == 15000
    assert rec.unobserved.num_rows == 1
    assert rec.meta.acquisition.method.value == "traffic_simulation"


def test_conformance_recording_validates_without_errors(conformance_path):
    report = aveas_format.validate(conformance_path)
    assert report.failures == []
    assert report.counts["error"] == 0, report.flatten(("code", "message"))


def test_conformance_lon_lat_agree_with_our_georeferencing(conformance_path):
    rec = aveas_format.open(conformance_path)
    frame = LocalFrame.of(rec)
    s = rec.states
    lon, lat = frame.to_wgs84(s.column("x").to_numpy(), s.column("y").to_numpy())
    assert np.abs(lon - s.column("lon").to_numpy()).max() < 1e-9
    assert np.abs(lat - s.column("lat").to_numpy()).max() < 1e-9


def test_conformance_road_coordinates_agree_with_our_map_engine(conformance_path):
    rec = aveas_format.open(conformance_path)
    s = rec.states
    proj = rec.map.world_to_road(s.column("x").to_numpy(), s.column("y").to_numpy())
    assert np.abs(proj.s - s.column("road_s").to_numpy()).max() < 1e-6
    assert np.abs(proj.t - s.column("road_t").to_numpy()).max() < 1e-6
    assert (proj.lane_id == s.column("lane_id").to_numpy()).all()
