"""Lanelet2 -> OpenDRIVE on the public Lanelet2 maps (../shared) and on maps written here."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_common import shared
from helpers_lanelet2 import ORIGIN, centre_deviation, crossroads, off_centre
from helpers_opendrive import xsd_18_errors

from aveas_format.errors import MapError
from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive, read_osm
from aveas_format.opendrive.lanelet2.lanelets import read_lanelets
from aveas_format.opendrive.lanelet2.osm import projection

KARLSRUHE = ("data", "real", "lanelet2", "lanelet2__mapping_example.osm")
INTERACTION = ("data", "real", "lanelet2", "interaction__TestScenarioForScripts.osm")


def _lanelets(path, origin, kind):
    m = read_osm(path)
    x, y = projection(kind, *origin).forward(m.lat, m.lon)
    return read_lanelets(m, x, y)[0], m


@pytest.mark.realdata
@pytest.mark.parametrize("parts,origin,kind", [(KARLSRUHE, (49.0, 8.4), "tmerc"), (INTERACTION, (0.0, 0.0), "utm")],
                         ids=["karlsruhe", "interaction"])
def test_public_maps_convert_completely_and_check_clean(parts, origin, kind):
    path = shared(*parts)
    conv = lanelet2_to_opendrive(path, origin=origin, projection_kind=kind)
    lanelets, osm = _lanelets(path, origin, kind)
    relations = {r.id for r in osm.relations.values() if r.tags.get("type") == "lanelet"}
    # every lanelet accounted for: a lane, a crosswalk object, or named in a warning
    named = {int(w.split()[1].rstrip(":")) for w in conv.warnings if w.startswith("lanelet ")}
    assert relations == set(conv.lanelet_lanes) | set(conv.crosswalks) | named
    net = conv.network()
    assert [f.message for f in net.check() if f.severity == "error"] == []
    assert xsd_18_errors(conv.xodr) == []
    # lane centres against the centre line computed properly from the bounds
    d = centre_deviation(net, lanelets, conv.lanelet_lanes)
    assert np.percentile(d, 95) <= 0.2


@pytest.mark.realdata
def test_karlsruhe_structure_and_regulatory_elements():
    conv = lanelet2_to_opendrive(shared(*KARLSRUHE), origin=(49.0, 8.4))
    assert len(conv.lanelet_lanes) + len(conv.crosswalks) == conv.lanelets == 371
    assert conv.junctions >= 5 and conv.stats["connecting_roads"] >= 50
    assert conv.signals == 6  # the map's six traffic-light regulatory elements, each on its lanes
    net = conv.network()
    sig = [s for r in net.roads.values() for s in r.signals]
    assert len(sig) >= 6 and all('dynamic="yes"' in s.xml and "<validity" in s.xml for s in sig)
    assert any(o.type == "crosswalk" for r in net.roads.values() for o in r.objects)
    # the map's one speed-limit element (a zone-30 sign) is referenced by no lanelet: named
    assert any(w.startswith("speed-limit regulatory element 45390") for w in conv.warnings)


@pytest.mark.realdata
@pytest.mark.parametrize("parts,origin", [(KARLSRUHE, (49.0, 8.4)), (INTERACTION, (0.0, 0.0))],
                         ids=["karlsruhe", "interaction"])
def test_bounds_and_orientation_equal_lanelet2s_own(parts, origin):
    """External reference: Lanelet2 itself (PyPI lanelet2) reads the same bounds, in the same
    direction, at the same UTM coordinates (its UtmProjector)."""
    lanelet2 = pytest.importorskip("lanelet2", reason="PyPI lanelet2 (the reference) is not installed")
    from lanelet2.io import Origin
    from lanelet2.projection import UtmProjector

    path = shared(*parts)
    ours, _ = _lanelets(path, origin, "utm")
    ref = lanelet2.io.load(str(path), UtmProjector(Origin(*origin)))
    assert {ll.id for ll in ref.laneletLayer} == set(ours)
    for ll in ref.laneletLayer:
        left = np.array([[p.x, p.y] for p in ll.leftBound])
        right = np.array([[p.x, p.y] for p in ll.rightBound])
        np.testing.assert_allclose(ours[ll.id].left, left, atol=1e-6)
        np.testing.assert_allclose(ours[ll.id].right, right, atol=1e-6)


@pytest.mark.realdata
def test_interaction_map_two_opposite_lanes_in_utm31():
    conv = lanelet2_to_opendrive(shared(*INTERACTION), origin=(0.0, 0.0), projection_kind="utm")
    assert conv.geo_reference.startswith("+proj=utm +zone=31 ") and conv.offset[0] == pytest.approx(166021.443, abs=1e-3)
    net = conv.network()
    assert len(net.roads) == 1
    road = next(iter(net.roads.values()))
    lanes = road.lane_sections[0]
    assert [ln.id for ln in lanes.left] == [1] and [ln.id for ln in lanes.right] == [-1]
    # lanelet 21 runs towards -x: the left lane (against s under right-hand traffic)
    _, _, _, h = net.road_to_world(road.id, [1.0], [0.0])
    assert (conv.lanelet_lanes[21][2] == 1) == (np.cos(h[0]) > 0)
    pr = net.world_to_road([50.0, 50.0], [2.5, 5.5])
    assert list(pr.lane_id) == [conv.lanelet_lanes[20][2], conv.lanelet_lanes[21][2]]
    assert np.allclose(np.abs(pr.lane_offset), 0.0, atol=0.02)


def test_crossroads_junction_connections_and_signals():
    text, ids = crossroads()
    conv = lanelet2_to_opendrive(text, origin=ORIGIN)
    assert conv.warnings == []
    net = conv.network()
    assert conv.junctions == 1 and conv.stats["connecting_roads"] == 12  # one per turning lanelet
    j = next(iter(net.junctions.values()))
    assert len(j.connections) == 12
    # each connecting road: from an arm's incoming lane to another arm's outgoing lane
    for c in j.connections:
        road = net.roads[c.connecting_road]
        assert road.junction == j.id and road.predecessor.element_id == c.incoming_road
        assert road.successor.element_id != c.incoming_road
        assert [(ll.from_lane, ll.to_lane) for ll in c.lane_links] == [(1, -1)]
    arms = [r for r in net.roads.values() if r.junction is None]
    assert len(arms) == 4 and all(r.predecessor.element_type == "junction" for r in arms)
    assert all(abs(ln.speeds[0][1] - 50 / 3.6) < 1e-9 for r in arms for ln in r.lane_sections[0].right)
    assert conv.signals == 1 and len(conv.crosswalks) == 1
    assert [f for f in net.check() if f.severity != "info"] == []
    # lanes exactly where the lanelets are
    lanelets, _ = _lanelets(text, ORIGIN, "tmerc")
    d = centre_deviation(net, lanelets, conv.lanelet_lanes)
    assert np.percentile(d, 95) < 0.03


def test_off_centre_is_zero_on_the_true_centre():
    left = np.array([[0.0, 2.0], [10.0, 2.0], [20.0, 3.0]])
    right = np.array([[0.0, -2.0], [10.0, -2.0], [20.0, -1.0]])
    assert off_centre(np.array([[5.0, 0.0], [15.0, 0.5]]), left, right) == pytest.approx([0.0, 0.0], abs=1e-9)
    assert off_centre(np.array([[5.0, 0.3]]), left, right) == pytest.approx([0.3])


def test_broken_lanelets_are_named_not_lost():
    text, _ = crossroads()
    way = text.split("<way id='")[1].split("'")[0]
    # a lanelet whose right way is missing from the file
    text = text.replace("</osm>", "  <relation id='999999' visible='true' version='1'>\n"
                        f"    <member type='way' ref='{way}' role='left' />\n"
                        "    <member type='way' ref='424242' role='right' />\n"
                        "    <tag k='type' v='lanelet' />\n  </relation>\n</osm>")
    conv = lanelet2_to_opendrive(text, origin=ORIGIN)
    assert any(w.startswith("lanelet 999999: not converted: its bound way 424242 is not in the file")
               for w in conv.warnings)


@pytest.mark.parametrize("text,match", [
    ("<osm><node id='1' lat='x' lon='8'/></osm>", "node 1: lat='x'"),
    ("<notosm/>", "not <osm>"),
    ("<osm><node id='1' lat='49' lon='8'/><way id='2'><nd ref='7'/><nd ref='1'/></way>"
     "<relation id='3'><member type='way' ref='2' role='left'/><member type='way' ref='2' role='right'/>"
     "<tag k='type' v='lanelet'/></relation></osm>", None),
    ("<osm><node id='1' lat='49' lon='8'", "not well-formed"),
])
def test_malformed_osm_is_a_clear_error(text, match):
    if match is None:  # a way naming a missing node: no lanelet left to convert
        with pytest.raises(MapError, match="no lanelet could be converted: lanelet 3: not converted: .*way 2 names node 7, which is not in the file"):
            lanelet2_to_opendrive(text)
        return
    with pytest.raises(MapError, match=match):
        lanelet2_to_opendrive(text)
