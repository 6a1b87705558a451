"""Fixtures of the OpenDRIVE tests."""

from __future__ import annotations

import pytest
from helpers_common import realdata_params
from helpers_opendrive import REAL_MAPS, fixture_map, real_map

from aveas_format.opendrive import RoadNetwork


@pytest.fixture(params=realdata_params(REAL_MAPS))
def real_net(request) -> RoadNetwork:
    """Each real map of ../shared/data/xodr."""
    return real_map(request.param)


@pytest.fixture
def geom_net() -> RoadNetwork:
    return fixture_map("geometry_types.xodr")
