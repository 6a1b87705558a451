"""Reader: header, roads, lanes, junctions, objects; tolerance of real files; errors with lines."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_opendrive import DATA, fixture_map, real_map

from aveas_format.errors import MapError, RecordingIOError
from aveas_format.opendrive import load_map


def test_header_of_fixture(geom_net):
    h = geom_net.header
    assert h.version == "1.6"
    assert h.geo_reference.startswith("+proj=tmerc +lat_0=49")
    assert h.offset == (1000.0, 2000.0, 5.0, 0.1)
    assert h.line == 6


def test_roads_lanes_junctions_objects(geom_net):
    assert set(geom_net.roads) == {
        "line",
        "arc",
        "spiral",
        "spiral_flat",
        "spiral_tiny",
        "poly3",
        "ppoly_arclength",
        "ppoly_normalized",
        "border",
        "sections",
    }
    line = geom_net.roads["line"]
    assert line.length == 100.0 and line.junction is None
    assert line.successor.element_type == "junction" and line.successor.element_id == "J1"
    assert line.types[0].type == "motorway"
    assert line.types[0].speed_max_ms == pytest.approx(130 / 3.6)
    sec = line.lane_sections[0]
    assert [ln.id for ln in sec.left] == [1]
    assert [ln.id for ln in sec.right] == [-1, -2, -3]
    assert sec.right[2].type == "sidewalk"
    assert sec.center.road_marks[0].type == "solid"
    assert line.objects[0].id == "o1" and line.objects[0].t == -12.0 and line.objects[0].attributes["height"] == "1.0"
    assert line.signals[0].type == "274" and line.signals[0].s == 20.0 and line.signals[0].line is not None
    assert line.elevation[0].b == 0.01 and line.superelevation[0].a == 0.02
    sections = geom_net.roads["sections"]
    assert sections.junction == "J1"
    assert [s.s for s in sections.lane_sections] == [0.0, 50.0, 50.0078]
    assert len(sections.lane_offset) == 3
    assert sections.lane_sections[0].right[0].successors == [-1]
    j = geom_net.junctions["J1"]
    assert j.connections[0].incoming_road == "line" and j.connections[0].connecting_road == "sections"
    assert [(ll.from_lane, ll.to_lane) for ll in j.connections[0].lane_links] == [(-1, -1), (-2, -2)]
    pp = geom_net.roads["ppoly_normalized"].geometries[0]
    assert pp.kind == "paramPoly3" and pp.params["p_range"] == "normalized" and pp.params["bU"] == 80.0
    border = geom_net.roads["border"].lane_sections[0]
    assert border.left[0].uses_border and not border.right[1].uses_border


def test_quirks_tolerated():
    net = fixture_map("quirks.xodr")  # comment before <?xml ...?>, empty header, missing attributes
    assert net.header.version == "1.4"
    assert net.header.geo_reference is None and net.header.offset is None
    road = net.roads["7"]
    assert road.name == "" and road.junction is None
    assert road.lane_sections[0].right[1].type == "none"
    assert [g.kind for g in road.geometries] == ["line", "spiral", "arc"]
    assert road.lane_sections[2].s - road.lane_sections[1].s == pytest.approx(0.0078)
    # the degenerate spiral behaves as a line
    x, y, h, k = net.reference_line("7", [125.0])
    assert x[0] == pytest.approx(125.02) and y[0] == pytest.approx(0.01) and h[0] == 0.0 and k[0] == 0.0


def test_bytes_text_and_path_inputs():
    raw = (DATA / "quirks.xodr").read_bytes()
    assert list(load_map(raw).roads) == ["7"]
    assert list(load_map(raw.decode()).roads) == ["7"]
    assert load_map(DATA / "quirks.xodr").path.endswith("quirks.xodr")


def test_namespace_and_encoding_after_a_comment():
    body = (
        '<!-- Straße -->\n<?xml version="1.0" encoding="ISO-8859-1"?>\n'
        '<OpenDRIVE xmlns="http://code.asam.net/simulation/standard/opendrive_schema">'
        '<header revMajor="1" revMinor="8" name="Straße"/>\n' + _GOOD_ROAD + "</OpenDRIVE>"
    )
    net = load_map(body.encode("latin-1"))
    assert net.header.name == "Straße" and net.header.version == "1.8"
    assert net.roads["1"].line == 4
    assert net.world_to_road([5.0], [-1.0]).lane_id.tolist() == [-1]


def test_missing_file():
    with pytest.raises(RecordingIOError, match="not found"):
        load_map(DATA / "nope.xodr")


_GOOD_ROAD = """<road length="10" id="1" junction="-1"><planView>
<geometry s="0" x="0" y="0" hdg="0" length="10"><line/></geometry></planView>
<lanes><laneSection s="0"><center><lane id="0"/></center>
<right><lane id="-1" type="driving"><width sOffset="0" a="3"/></lane></right></laneSection></lanes></road>"""


@pytest.mark.parametrize(
    ("body", "line", "match"),
    [
        ('<header/>\n<road length="abc" id="1"/>', 3, "length='abc' is not a number"),
        (
            '<header/>\n<road id="1" length="5">\n<planView><geometry s="0" x="0" y="0" hdg="0" length="5"/></planView></road>',
            4,
            "exactly one of",
        ),
        (
            '<header/>\n<road id="1" length="5">\n<planView><geometry s="0" x="0" hdg="0" length="5"><line/></geometry></planView></road>',
            4,
            "'y'",
        ),
        ('<header/>\n<road id="1" length="5"><lanes/></road>', 3, "no <planView>"),
        ("<header/>\n" + _GOOD_ROAD + "\n" + _GOOD_ROAD, 7, "duplicate road id"),
        (
            '<header/>\n<road id="1" length="5">\n<planView><geometry s="0" x="0" y="0" hdg="0" length="5"><paramPoly3 pRange="bogus"/></geometry></planView></road>',
            4,
            "pRange",
        ),
        ("<header/>\n<road id='1' length='5'>\n<unclosed>", 4, "not well-formed"),
    ],
)
def test_malformed_maps_name_the_line(body, line, match):
    text = f'<?xml version="1.0"?>\n<OpenDRIVE>{body}</OpenDRIVE>'
    with pytest.raises(MapError, match=match) as info:
        load_map(text)
    assert info.value.where.get("line") == line
    assert isinstance(info.value, ValueError)


def test_error_names_the_path(tmp_path):
    p = tmp_path / "bad.xodr"
    p.write_text('<?xml version="1.0"?>\n<OpenDRIVE>\n<header/>\n<road id="1" length="x"/></OpenDRIVE>')
    with pytest.raises(MapError) as info:
        load_map(p)
    assert str(p) in str(info.value) and "line 4" in str(info.value)


def test_wrong_root():
    with pytest.raises(MapError, match="not <OpenDRIVE>"):
        load_map("<foo/>")


@pytest.mark.parametrize(
    ("name", "n_roads", "n_junctions", "version"),
    [
        ("opendrive-test-files__Town04.xodr", 242, 27, "1.4"),
        ("opendrive-test-files__Town03.xodr", 279, 34, "1.4"),
        ("esmini__multi_intersections.xodr", 63, 5, "1.4"),
        ("esmini__parking_demo.xodr", None, None, "1.7"),
        ("qc-opendrive__Ex_Entry_Exit.xodr", None, None, "1.8"),
    ],
)
@pytest.mark.realdata
def test_real_map_counts(name, n_roads, n_junctions, version):
    net = real_map(name)
    assert net.header.version == version
    if n_roads is not None:
        assert len(net.roads) == n_roads
        assert len(net.junctions) == n_junctions


def test_every_real_map_loads(real_net):
    assert len(net_roads := real_net.roads) > 0
    total = sum(r.length for r in net_roads.values())
    assert total > 0
    xmin, ymin, xmax, ymax = real_net.bounds
    assert xmax > xmin and ymax > ymin


@pytest.mark.realdata
def test_real_map_features():
    e6 = real_map("esmini__e6mini.xodr")
    assert "+proj=utm" in e6.header.geo_reference
    assert any(
        g.kind == "paramPoly3" and g.params["p_range"] == "arcLength" for r in e6.roads.values() for g in r.geometries
    )
    assert sum(len(r.objects) for r in e6.roads.values()) == 6
    town = real_map("opendrive-test-files__Town04.xodr")
    assert town.header.geo_reference.startswith("+lat_0=4.9")
    tiny = [b.s - a.s for r in town.roads.values() for a, b in zip(r.lane_sections, r.lane_sections[1:])]
    assert min(tiny) < 0.01  # 7.8 mm lane sections
    ee = real_map("qc-opendrive__Ex_Entry_Exit.xodr")
    direct = [j for j in ee.junctions.values() if j.type == "direct"]
    assert direct and direct[0].connections[0].linked_road is not None
    mi = real_map("esmini__multi_intersections.xodr")
    assert sum(len(r.signals) for r in mi.roads.values()) == 127
    assert sum(g.kind == "spiral" for r in mi.roads.values() for g in r.geometries) == 56
    park = real_map("esmini__parking_demo.xodr")
    spirals = [(r.id, g) for r in park.roads.values() for g in r.geometries if g.kind == "spiral"]
    assert any(g.params["curv_start"] == g.params["curv_end"] for _, g in spirals)
    assert any(abs(g.params["curv_start"]) == 1e-9 for _, g in spirals)
    for rid, g in spirals:
        x, y, h, k = park.reference_line(rid, np.linspace(g.s, g.s + g.length, 11))
        assert np.isfinite(x).all() and np.isfinite(y).all()
