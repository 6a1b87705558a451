"""Helpers of the OpenDRIVE tests: paths of the hand-made fixtures and of the real maps in shared/."""

from __future__ import annotations

import importlib.util
from functools import lru_cache
from pathlib import Path

import pytest
from lxml import etree

from aveas_format.opendrive import RoadNetwork, load_map

from helpers_common import SHARED, shared

DATA = Path(__file__).resolve().parent / "opendrive" / "data"
#: names of the real maps in ../shared/data/xodr (none without ../shared)
REAL_MAPS = sorted(p.name for p in (SHARED / "data" / "xodr").glob("*.xodr"))
#: maps whose consecutive geometries meet to <= 1e-6 m in the file itself
CONTINUOUS_MAPS = {
    "esmini__e6mini.xodr",
    "esmini__fabriksgatan.xodr",
    "esmini__multi_intersections.xodr",
    "esmini__parking_demo.xodr",
    "esmini__velodrome.xodr",
}


def real_map(name: str) -> RoadNetwork:
    """A real map of ../shared/data/xodr, for a realdata test (skips without ../shared)."""
    return _load(shared("data", "xodr", name))


@lru_cache(maxsize=None)
def _load(path: Path) -> RoadNetwork:
    return load_map(path)


@lru_cache(maxsize=None)
def fixture_map(name: str) -> RoadNetwork:
    return load_map(DATA / name)


def xsd_16():
    """The official OpenDRIVE 1.6 XSD shipped by PyPI ``asam-qc-opendrive`` (skip without it)."""
    spec = importlib.util.find_spec("qc_opendrive")
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("asam-qc-opendrive (which ships the official XSD) is not installed")
    core = Path(next(iter(spec.submodule_search_locations))) / "schema" / "1.6.1" / "opendrive_16_core.xsd"
    if not core.exists():
        pytest.skip(f"no OpenDRIVE 1.6 XSD at {core}")
    return etree.XMLSchema(etree.parse(str(core)))
