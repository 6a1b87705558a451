"""Fixtures of the OpenDRIVE tests."""

from __future__ import annotations

import pytest
from helpers_opendrive import REAL_MAPS, fixture_map, real_map, require_real_maps

from aveas_format.opendrive import RoadNetwork


@pytest.fixture(params=REAL_MAPS or ["<none>"])
def real_net(request) -> RoadNetwork:
    require_real_maps()
    return real_map(request.param)


@pytest.fixture
def geom_net() -> RoadNetwork:
    return fixture_map("geometry_types.xodr")
