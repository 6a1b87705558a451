"""Writer and builders: valid OpenDRIVE 1.8 (and older revisions on request), exact round trips."""

from __future__ import annotations


import numpy as np
import pytest
from lxml import etree
from helpers_opendrive import fixture_map, xsd_16, xsd_18_errors

from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import curved_highway, straight_highway
from aveas_format.opendrive.writer import write_xodr


def test_straight_highway():
    text = straight_highway(
        length=1000.0,
        lanes_right=3,
        lanes_left=2,
        lane_width=3.75,
        x0=10.0,
        y0=20.0,
        hdg=0.5,
        geo_reference="+proj=utm +zone=32 +ellps=WGS84",
    )
    net = load_map(text)
    assert net.header.version == "1.8"
    assert net.header.geo_reference == "+proj=utm +zone=32 +ellps=WGS84"
    road = net.roads["1"]
    assert road.length == 1000.0
    sec = road.lane_sections[0]
    assert [ln.id for ln in sec.left] == [1, 2] and [ln.id for ln in sec.right] == [-1, -2, -3]
    x, y, h, _ = net.reference_line("1", [0.0, 1000.0])
    np.testing.assert_allclose(x, [10.0, 10.0 + 1000 * np.cos(0.5)])
    np.testing.assert_allclose(y, [20.0, 20.0 + 1000 * np.sin(0.5)])
    inner, outer = net.lane_borders("1", [500.0], -3)
    np.testing.assert_allclose([inner[0], outer[0]], [-7.5, -11.25])
    assert [f for f in net.check() if f.severity == "error"] == []


def test_curved_highway_geometry():
    net = load_map(curved_highway(length=800.0, radius=-400.0, straight=100.0, spiral=60.0, lanes_right=2))
    kinds = [g.kind for g in net.roads["1"].geometries]
    assert kinds == ["line", "spiral", "arc"]
    _, _, h, k = net.reference_line("1", [800.0])
    assert k[0] == pytest.approx(-1 / 400)
    assert h[0] == pytest.approx(-(30 / 400 + 640 / 400))
    findings = net.check()
    assert [f.code for f in findings if f.code.startswith("geometry")] == []


@pytest.mark.parametrize(
    "kwargs",
    [dict(length=-1.0), dict(lanes_right=0, lanes_left=0), dict(lane_width=0.0)],
)
def test_builder_rejects_bad_arguments(kwargs):
    with pytest.raises(ValueError):
        straight_highway(**kwargs)


def test_curved_rejects_fold():
    with pytest.raises(ValueError, match="beyond the curve's centre"):
        curved_highway(radius=5.0, lanes_left=2, lane_width=3.5)


def test_generated_maps_validate_against_the_official_xsd():
    for text in (
        straight_highway(geo_reference="+proj=tmerc +lat_0=49 +lon_0=8"),
        curved_highway(radius=300.0, spiral=40.0, straight=10.0, lanes_left=2),
        write_xodr(fixture_map("geometry_types.xodr")),
    ):
        assert 'revMinor="8"' in text
        assert xsd_18_errors(text) == []


def test_older_revisions_on_request_validate_against_their_xsd():
    """rev_minor=6 leaves out what only 1.7+/1.8 have (lane direction, overlapZone, elementS)."""
    xsd = xsd_16()
    net = fixture_map("geometry_types.xodr")
    text = write_xodr(net, rev_minor=6)
    assert 'revMinor="6"' in text
    assert xsd.validate(etree.fromstring(text.encode())), xsd.error_log
    assert load_map(text).header.version == "1.6"


def test_1_7_attributes_are_written_to_1_8_and_read_back():
    from aveas_format.opendrive.model import RoadLink

    net = load_map(straight_highway(lanes_left=1))
    road = net.roads["1"]
    road.lane_sections[0].left[0].direction = "reversed"
    road.successor = RoadLink("road", "1", "start", element_s=0.0, element_dir="+")
    back = load_map(write_xodr(net))
    assert back.roads["1"].lane_sections[0].left[0].direction == "reversed"
    assert (back.roads["1"].successor.element_s, back.roads["1"].successor.element_dir) == (0.0, "+")
    assert "direction=" not in write_xodr(net, rev_minor=6)


def test_write_read_round_trip(real_net):
    net2 = load_map(write_xodr(real_net))
    assert list(net2.roads) == list(real_net.roads)
    assert list(net2.junctions) == list(real_net.junctions)
    assert net2.header.geo_reference == real_net.header.geo_reference
    smp = real_net.sample_lane_points(2000, seed=4, drivable_only=False)
    a = real_net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    b = net2.road_to_world(smp["road_id"], smp["s"], smp["t"])
    for u, v in zip(a, b):
        np.testing.assert_array_equal(u, v)
    la = real_net.lane_at(smp["road_id"], smp["s"], smp["t"])
    lb = net2.lane_at(smp["road_id"], smp["s"], smp["t"])
    np.testing.assert_array_equal(la[0], lb[0])
    n_obj = lambda n: sum(len(r.objects) + len(r.signals) for r in n.roads.values())  # noqa: E731
    assert n_obj(net2) == n_obj(real_net)
    assert sum(len(j.connections) for j in net2.junctions.values()) == sum(
        len(j.connections) for j in real_net.junctions.values()
    )


def test_write_fixture_keeps_everything(geom_net):
    net2 = load_map(write_xodr(geom_net))
    assert net2.header.offset == geom_net.header.offset
    b1, b2 = geom_net.roads["border"], net2.roads["border"]
    assert b2.lane_sections[0].left[0].uses_border
    np.testing.assert_array_equal(b1.lane_sections[0].right[0].borders, b2.lane_sections[0].right[0].borders)
    assert net2.roads["line"].types[0].speed_max_ms == pytest.approx(130 / 3.6)
    assert net2.roads["line"].signals[0].attributes["subtype"] == "130"
    assert net2.roads["ppoly_normalized"].geometries[0].params["p_range"] == "normalized"
