"""Test helpers shared by every test directory (tests/ is on pytest's pythonpath): paths to
shared data and small valid recordings built from plain arrays."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.mapref.build import build_recording

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"
SHARED = ROOT.parent / "shared"
CONFORMANCE = SHARED / "data" / "conformance" / "highway.aveas"
STRAIGHT_MAP = DATA / "straight.xodr"


def small_recording(n: int = 4, steps: int = 50, rate: float = 10.0, seed: int = 1, **kw):
    """n vehicles driving along the straight test map, `steps` samples each."""
    rng = np.random.default_rng(seed)
    pid = np.repeat(np.arange(n, dtype=np.int64), steps)
    t = np.tile(np.arange(steps) / rate, n)
    lane = np.repeat(rng.integers(1, 4, n), steps)
    v = np.repeat(rng.uniform(20, 35, n), steps)
    x = np.repeat(rng.uniform(10, 300, n), steps) + v * t
    y = -(lane - 0.5) * 3.5
    participants = {
        "participant_id": np.arange(n, dtype=np.int64),
        "class": np.array(["car", "truck", "van", "car", "bus"] * n)[:n],
        "length": rng.uniform(4, 12, n),
        "width": rng.uniform(1.7, 2.5, n),
        "length_std": np.full(n, 0.2),
        "width_std": np.full(n, 0.1),
    }
    states = {
        "participant_id": pid, "time": t, "x": x, "y": y, "heading": np.zeros(n * steps),
        "vx": v, "vy": np.zeros(n * steps),
        "x_std": np.full(n * steps, 0.1), "y_std": np.full(n * steps, 0.1),
        "heading_std": np.full(n * steps, 0.01), "vx_std": np.full(n * steps, 0.2),
        "vy_std": np.full(n * steps, 0.2),
    }
    kw.setdefault("partner", "test")
    kw.setdefault("method", "aerial")
    kw.setdefault("recording_id", f"test-{seed}")
    kw.setdefault("coverage", "POLYGON ((0 -12, 1000 -12, 1000 2, 0 2, 0 -12))")
    return build_recording(map_source=STRAIGHT_MAP, participants=participants, states=states, **kw)




def minimal_meta(**over):
    """A minimal valid recording.json dict."""
    d = {
        "format_version": "1.0.0", "recording_id": "r1", "start_time": "2024-05-13T08:15:00Z",
        "duration_s": 10.0, "nominal_rate_hz": 25.0,
        "acquisition": {"method": "aerial", "partner": "KIT"}, "provenance": "natural",
        "location": {"lon": 8.4, "lat": 49.0}, "crs": "EPSG:25832",
        "map": {"file": "map.xodr", "sha256": "0" * 64, "opendrive_version": "1.6"},
        "rights": {"right_of_use": "research_only", "license": "CC-BY-4.0", "owner": "KIT"},
        "tables": {},
    }
    d.update(over)
    return d
