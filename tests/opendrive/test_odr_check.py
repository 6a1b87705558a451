"""check(): one passing and one failing map per rule, asserted as (code, road_id, line) tuples."""

from __future__ import annotations

import pytest
from helpers_opendrive import fixture_map

from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import straight_highway


def _flat(findings, codes=None):
    return [(f.code, f.road_id, f.line) for f in findings if codes is None or f.code in codes]


def _road(
    rid="1", extra="", lanes='<lane id="-1" type="driving"><width sOffset="0" a="3.5"/></lane>', link="", geoms=None
):
    geoms = geoms or '<geometry s="0" x="0" y="0" hdg="0" length="100"><line/></geometry>'
    return (
        f'<road id="{rid}" length="100" junction="-1">{link}\n<planView>{geoms}</planView>\n'
        f'<lanes><laneSection s="0"><center><lane id="0"/></center><right>{lanes}</right></laneSection></lanes>{extra}</road>'
    )


def _map(*roads, header="<header/>", junctions=""):
    return load_map(
        '<?xml version="1.0"?>\n<OpenDRIVE>' + header + "\n" + "\n".join(roads) + junctions + "</OpenDRIVE>"
    )


def test_clean_maps_have_no_findings():
    assert fixture_map("geometry_types.xodr").check() == []
    net = load_map(straight_highway(geo_reference="+proj=utm +zone=32 +datum=WGS84"))
    assert net.check() == []


def test_gap_and_length():
    net = fixture_map("quirks.xodr")
    assert _flat(net.check(), {"geometry.gap"}) == [("geometry.gap", "7", 10)]
    gap = next(f for f in net.check() if f.code == "geometry.gap")
    assert gap.value == pytest.approx((0.02**2 + 0.01**2) ** 0.5)
    geoms = '<geometry s="0" x="0" y="0" hdg="0" length="50"><line/></geometry>\n<geometry s="50" x="50" y="0" hdg="0.1" length="40"><line/></geometry>'
    codes = _flat(_map(_road(geoms=geoms)).check(), {"geometry.heading_jump", "road.length_mismatch"})
    assert codes == [("geometry.heading_jump", "1", 5), ("road.length_mismatch", "1", 3)]


def test_negative_width():
    net = _map(_road(lanes='<lane id="-1" type="driving"><width sOffset="0" a="1.0" b="-0.02"/></lane>'))
    f = _flat(net.check(), {"lane.negative_width"})
    assert f == [("lane.negative_width", "1", 5)]


def test_broken_links():
    link = '<link><successor elementType="road" elementId="404" contactPoint="start"/><predecessor elementType="junction" elementId="J9"/></link>'
    lanes = '<lane id="-1" type="driving"><link><successor id="-7"/></link><width sOffset="0" a="3.5"/></lane>'
    junction = (
        '<junction id="J1"><connection id="0" incomingRoad="1" connectingRoad="ghost" contactPoint="start"/></junction>'
    )
    net = _map(
        _road(link=link),
        _road(
            rid="2", lanes=lanes, link='<link><successor elementType="road" elementId="1" contactPoint="start"/></link>'
        ),
        junctions=junction,
    )
    got = sorted(_flat(net.check(), {"link.missing_road", "link.missing_junction", "link.missing_lane"}), key=str)
    assert got == sorted(
        [
            ("link.missing_road", "1", 3),
            ("link.missing_junction", "1", 3),
            ("link.missing_lane", "2", 8),
            ("link.missing_road", None, 8),
        ],
        key=str,
    )


@pytest.mark.parametrize(
    ("geo", "code"),
    [
        ("+lat_0=4.9e+1 +lon_0=8.0e+0", "georef.no_proj"),
        ("+proj=utm +lat_0=37 +lon_0=-122 +datum=WGS84", "georef.utm_no_zone"),
        ("+proj=nosuchprojection +ellps=WGS84", "georef.unparseable"),
        (None, "georef.missing"),
    ],
)
def test_georeference(geo, code):
    header = f"<header><geoReference><![CDATA[{geo}]]></geoReference></header>" if geo else "<header/>"
    net = _map(_road(), header=header)
    assert _flat(net.check()) == [(code, None, 2)]


def test_lane_width_noise_is_a_warning_below_the_tolerance():
    """Issue 18, point 8: a few mm of negative width at a section start (a real RoadRunner export
    has -2.6 mm) is numerical noise: a warning below WIDTH_TOL (1 cm), an error beyond."""
    from aveas_format.opendrive.check import WIDTH_TOL

    def lanes(a):
        return (f'<lane id="-1" type="driving"><width sOffset="0" a="{a}" b="0.5" c="0" d="0"/></lane>'
                '<lane id="-2" type="driving"><width sOffset="0" a="3.5"/></lane>')

    noisy = [f for f in _map(_road(lanes=lanes(-0.0026))).check() if f.code != "georef.missing"]
    assert [(f.code, f.severity) for f in noisy] == [("lane.width_noise", "warning")]
    assert "-0.0026 m (within the 10 mm tolerance" in noisy[0].message
    bad = [f for f in _map(_road(lanes=lanes(-2 * WIDTH_TOL))).check() if f.code != "georef.missing"]
    assert [(f.code, f.severity) for f in bad] == [("lane.negative_width", "error")]


def test_border_records_are_signed_t_in_check_and_projection():
    """<border> is the outer border's signed t (ASAM OpenDRIVE 1.8 11.6.2): a right lane's border at
    a positive t lies left of the reference line. map check says so (border_sign, and the negative
    width that follows) and the projection reads it the same way: the lane's borders are t = 0 and
    t = +2, a negative width on the right side, so no point lies in it (neither at t = -1 nor at
    t = +1): the map is defective, as map check says, rather than silently reinterpreted."""
    import numpy as np

    net = _map(_road(lanes='<lane id="-1" type="driving"><border sOffset="0" a="2.0"/></lane>'))
    codes = [(f.code, f.severity) for f in net.check() if f.code != "georef.missing"]
    assert codes == [("lane.border_sign", "warning"), ("lane.negative_width", "error")]
    inner, outer = net.lane_borders("1", np.array([50.0]), np.array([-1]))
    assert (inner[0], outer[0]) == (0.0, 2.0)
    lane, _ = net.lane_at("1", np.array([50.0, 50.0]), np.array([-1.0, 1.0]))
    assert lane.tolist() == [0, 0]
    # the usual reading: a right lane's border at a negative t, no finding
    ok = _map(_road(lanes='<lane id="-1" type="driving"><border sOffset="0" a="-2.0"/></lane>'))
    assert [f.code for f in ok.check()] == ["georef.missing"]
