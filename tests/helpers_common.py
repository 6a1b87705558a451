"""Test helpers shared by every test directory (tests/ is on pytest's pythonpath): paths, the
access to the real data in ``../shared`` and small valid recordings built from plain arrays.

Real data (``../shared`` beside the checkout) is read through :func:`shared` (inside a test or a
fixture, never at import time: a plain clone must collect), by fixtures declared with
:func:`realdata_fixture`, or by the parameters of :func:`realdata_params`. Every test that does so
carries the marker ``realdata``: fixtures and parameters apply it at collection, a test that calls
:func:`shared` itself says ``@pytest.mark.realdata`` (``shared`` fails a test that does not, so
the marks stay complete). Without ``../shared`` each such test is skipped with the one reason
:data:`SHARED_ABSENT`; tests/conftest.py counts them in pytest's closing line.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from aveas_format.mapref.build import build_recording

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).resolve().parent / "data"
SHARED = ROOT.parent / "shared"
STRAIGHT_MAP = DATA / "straight.xodr"

#: the one skip reason of every real-data test on a plain clone
SHARED_ABSENT = (f"real data: ../shared is not beside the checkout ({SHARED} is missing; "
                 "see tests/README.md)")
REALDATA = pytest.mark.realdata
#: names of the fixtures declared with realdata_fixture (tests using them are marked realdata)
REALDATA_FIXTURES: set[str] = set()
#: the test being run (set by tests/conftest.py), for shared()'s check of the marker
CURRENT_TEST: list[Any] = [None]


def shared(*parts: str) -> Path:
    """``../shared/PARTS`` for the running real-data test or fixture; skips the test with
    :data:`SHARED_ABSENT` when ``../shared`` is absent. Fails a test that is not marked
    ``realdata`` (mark it, or take the data from a :func:`realdata_fixture`), and a file missing
    from a present ``../shared`` (a wrong name is a bug, not a skip)."""
    item = CURRENT_TEST[0]
    if item is None:
        raise RuntimeError("shared() is called inside a test or a fixture, never at import time "
                           "(a checkout without ../shared must collect)")
    if item.get_closest_marker("realdata") is None:
        pytest.fail(f"{item.nodeid} reads ../shared/{'/'.join(parts)} but is not marked realdata: "
                    "add @pytest.mark.realdata or take the data from a realdata_fixture",
                    pytrace=False)
    if not SHARED.is_dir():
        pytest.skip(SHARED_ABSENT)
    path = SHARED.joinpath(*parts)
    if not path.exists():
        pytest.fail(f"real data: {path} is missing from ../shared", pytrace=False)
    return path


def realdata_fixture(fn: Callable | None = None, **kw: Any) -> Any:
    """``@pytest.fixture`` (same keywords) of a fixture that reads ``../shared`` (through
    :func:`shared`): every test that uses it, directly or through other fixtures, is marked
    ``realdata`` at collection (tests/conftest.py)."""

    def decorate(f: Callable) -> Any:
        REALDATA_FIXTURES.add(kw.get("name") or f.__name__)
        return pytest.fixture(**kw)(f)

    return decorate(fn) if fn is not None else decorate


def realdata_params(values: Iterable[Any], ids: Callable[[Any], str] = str) -> list:
    """Parameters (``pytest.param``, marked ``realdata``) of a test parametrised over real data
    found under ``../shared`` at collection; without ``../shared``, one parameter skipped with
    :data:`SHARED_ABSENT`."""
    values = list(values)
    if not SHARED.is_dir():
        return [pytest.param(None, id="shared-data-absent",
                             marks=(REALDATA, pytest.mark.skip(reason=SHARED_ABSENT)))]
    return [pytest.param(v, id=ids(v), marks=REALDATA) for v in values]


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


