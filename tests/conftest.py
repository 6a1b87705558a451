"""Shared fixtures: paths to shared data, small valid recordings built from plain arrays."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import aveas_format
from aveas_format.io.builder import build_recording

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


@pytest.fixture
def rec():
    return small_recording()


@pytest.fixture
def written(tmp_path, rec):
    """A small recording written in directory form."""
    return rec.write(tmp_path / "small.aveas")


@pytest.fixture(scope="session")
def conformance_path():
    if not CONFORMANCE.is_dir():
        pytest.skip(f"shared conformance recording not found at {CONFORMANCE}")
    return CONFORMANCE


def open_(path, **kw):
    return aveas_format.open(path, **kw)
