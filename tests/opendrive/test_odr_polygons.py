"""Lane polygons: areas, containment of lane points, section granularity."""

from __future__ import annotations

import pytest
import shapely
from helpers_opendrive import real_map

from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import straight_highway


def test_straight_highway_polygons():
    net = load_map(straight_highway(length=200.0, lanes_right=3, lanes_left=1, lane_width=3.5))
    polys = net.lane_polygons()
    assert sorted(p[2] for p in polys) == [-3, -2, -1, 1]
    for road_id, sec, _, poly in polys:
        assert road_id == "1" and sec == 0 and poly.is_valid
        assert abs(poly.area - 700.0) < 1e-6
    xmin, ymin, xmax, ymax = net.bounds
    assert xmin <= 0.0 and xmax >= 200.0 and ymin <= -10.5 and ymax >= 3.5


def test_polygons_contain_their_lane_points(geom_net):
    polys = {(r, s, lid): p for r, s, lid, p in geom_net.lane_polygons(step=0.5)}
    smp = geom_net.sample_lane_points(500, seed=2, margin=0.1)
    x, y, _, _ = geom_net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    for i in range(len(x)):
        rid = smp["road_id"][i]
        sec = geom_net.roads[rid].section_index(smp["s"][i])
        poly = polys[(rid, sec, int(smp["lane_id"][i]))]
        assert poly.buffer(1e-3).contains(shapely.Point(x[i], y[i]))


@pytest.mark.realdata
def test_real_map_polygons_drivable_only():
    net = real_map("opendrive-test-files__Town04.xodr")
    all_polys = net.lane_polygons(step=2.0)
    drivable = net.lane_polygons(step=2.0, drivable_only=True)
    assert 0 < len(drivable) < len(all_polys)
    area = sum(p.area for *_, p in drivable)
    assert area > 1e5  # Town04 has km of multi-lane highway


def test_spatial_index_geometry_query(geom_net):
    idx = geom_net.spatial_index
    _, chunks = idx.query_geometry(shapely.box(40.0, -2.0, 41.0, -1.0))
    roads = {geom_net.road_ids[r] for r in idx.road[chunks]}
    assert roads == {"line"}
