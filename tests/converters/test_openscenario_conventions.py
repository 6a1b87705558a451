"""OpenSCENARIO files as scenario tools write them (issue 42, points 2-4): CARLA's left-handed
frame (detected from the FileHeader, forced by ``-O handedness``), the one off-map warning of
every import, catalog entries of size 0 0 0, and logical scenarios (parameter variation files).
Small files of our own on the hand-made straight map (lanes -1..-3 of 3.5 m at y = -1.75, -5.25,
-8.75) and, with ../shared, on CARLA's Town04."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pyarrow.compute as pc
import pytest

import aveas_format
from aveas_format.converters.labels import CLASS_SIZE
from aveas_format.converters.registry import convert
from aveas_format.errors import FormatError
from aveas_format.mapref.offmap import OffMapWarning
from helpers_common import STRAIGHT_MAP, shared
from helpers_xosc import ent, follow, poly, states_of, teleport, vertex, xosc
from test_cli import cli


def run(path, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rec = convert("openscenario", [path], **kw)
    return rec, [x for x in w if issubclass(x.category, UserWarning)
                 and "GeoReference" not in type(x.message).__name__]


def off_map(caught) -> list[str]:
    return [str(w.message) for w in caught if issubclass(w.category, OffMapWarning)]


def carla(p, description="CARLA:cut-in"):
    """The scenario file ``p`` with its FileHeader description set (scenario_runner's mark)."""
    p.write_text(p.read_text().replace('description="t"', f'description="{description}"'))
    return p


# --- point 2: the frame of the file --------------------------------------------------------------

def _mirrored_scene(tmp_path):
    """A car on lane -1 (y = -1.75) written in CARLA's frame: y = +1.75, along a timed polyline
    (a vertex every 0.5 s), and a second car placed ``dy`` = +3.5 (CARLA: to the right) of the
    first, its heading turned by -0.2 (CARLA: clockwise): on lane -2 (y = -5.25)."""
    verts = [vertex(10 + 5 * i, 1.75, 0.5 * i) for i in range(11)]
    init = (teleport("A", '<WorldPosition x="10" y="1.75" h="0"/>', 10)
            .replace("</Private>", follow(poly(*verts),
                                          timing='<Timing domainAbsoluteRelative="absolute" '
                                                 'scale="1" offset="0"/>') + "</Private>")
            + teleport("B", '<RelativeObjectPosition entityRef="A" dx="5" dy="3.5">'
                            '<Orientation type="relative" h="-0.2"/></RelativeObjectPosition>'))
    return xosc(tmp_path, ent("A") + ent("B"), init,
                stop='<ConditionGroup><Condition name="end" delay="0" conditionEdge="rising">'
                     '<ByValueCondition><SimulationTimeCondition value="5" rule="greaterThan"/>'
                     '</ByValueCondition></Condition></ConditionGroup>')


def test_carla_frame_detected_from_the_header(tmp_path):
    """``CARLA:`` in the FileHeader description: y, headings and lateral offsets mirrored into
    the map's frame (what scenario_runner does the other way round); the cars land on their lanes
    and the recording says which frame was read and why."""
    p = carla(_mirrored_scene(tmp_path))
    rec, caught = run(p)
    a, b = states_of(rec, 0), states_of(rec, 1)
    assert np.allclose(a["y"], -1.75) and a["x"][0] == pytest.approx(10.0)
    assert a["x"][-1] == pytest.approx(60.0) and a["time"][-1] == pytest.approx(5.0)
    assert np.allclose(b["x"], 15.0) and np.allclose(b["y"], -5.25)
    assert np.allclose(b["heading"], 0.2)  # CARLA's -0.2 (clockwise) is 0.2 counter-clockwise
    assert rec.states["road_id"].null_count == 0
    assert [r.to_pylist() for r in (pc.unique(rec.states["lane_id"]),)] == [[-1, -2]]
    ext = rec.meta.extras["openscenario"]["handedness"]
    assert ext["frame"] == "left" and "CARLA:" in ext["why"]
    assert rec.meta.source.options["handedness"] == "left"
    assert off_map(caught) == []


def test_handedness_forced_and_the_off_map_warning(tmp_path):
    """Forced the other way, the same file lands mirrored: one warning says so, with the share,
    that y negated would fit, and the option to try; forcing ``left`` on an unmarked file
    mirrors it the same way as the header would."""
    p = carla(_mirrored_scene(tmp_path))
    rec, caught = run(p, options={"handedness": "right"})
    assert rec.states["road_id"].null_count == rec.states.num_rows  # all mirrored off the road
    (msg,) = off_map(caught)
    assert "converter openscenario: the recording is mostly off its map" in msg
    assert "(100.0 %) are on no road" in msg
    assert "with y negated (a left-handed frame, as CARLA's), 100% would be on a road" in msg
    assert "-O handedness=left" in msg and "--crs" in msg
    (tmp_path / "plain").mkdir()
    plain = carla(_mirrored_scene(tmp_path / "plain"), "a plain scenario")
    rec2, caught2 = run(plain, options={"handedness": "left"})
    assert np.allclose(states_of(rec2, 0)["y"], -1.75) and off_map(caught2) == []
    assert rec2.meta.extras["openscenario"]["handedness"]["why"] == "option handedness=left"


def test_right_handed_file_stays_as_it_is(tmp_path):
    """Without the mark, OpenSCENARIO's own frame: nothing is mirrored (the existing files)."""
    p = xosc(tmp_path, ent("A"), teleport("A", '<WorldPosition x="10" y="-5.25" h="0.1"/>'))
    rec, caught = run(p)
    s = states_of(rec)
    assert np.allclose(s["y"], -5.25) and np.allclose(s["heading"], 0.1)
    assert rec.meta.extras["openscenario"]["handedness"]["frame"] == "right"
    assert off_map(caught) == []


def test_carla_clothoid_turns_the_mirrored_way(tmp_path):
    """A clothoid of curvature +0.01 1/m in CARLA's frame turns clockwise: to the right in the
    map's frame, on the arc y = -1.75 - (1 - cos(k s)) / k."""
    shape = ('<Clothoid curvature="0.01" curvaturePrime="0" length="30" startTime="0" '
             'stopTime="3"><Position><WorldPosition x="0" y="1.75" h="0"/></Position></Clothoid>')
    init = teleport("A", '<WorldPosition x="0" y="1.75" h="0"/>', 10).replace(
        "</Private>", follow(shape, timing='<Timing domainAbsoluteRelative="absolute" scale="1" '
                                           'offset="0"/>') + "</Private>")
    rec, _ = run(carla(xosc(tmp_path, ent("A"), init)))
    s = states_of(rec)
    k, end = 0.01, 30.0
    assert s["y"][-1] == pytest.approx(-1.75 - (1 - math.cos(k * end)) / k, abs=0.02)
    assert s["x"][-1] == pytest.approx(math.sin(k * end) / k, abs=0.02)


@pytest.mark.realdata
def test_carla_scenario_on_town04(tmp_path):
    """CARLA's Town04 (its OpenDRIVE map): a car driving 190 m of lane -1 of road 45, written as
    a CARLA scenario (y and heading negated, ``CARLA:`` header) lands on that lane, equal to the
    map's own lane centre; read as right-handed it lands 0 % on the map and the warning says so."""
    from aveas_format.opendrive import load_map

    town = shared("data", "xodr", "opendrive-test-files__Town04.xodr")
    net = load_map(town)
    s = np.linspace(10.0, 200.0, 20)
    inner, outer = net.lane_borders("45", s, np.full(len(s), -1))
    x, y, _, h = net.road_to_world("45", s, 0.5 * (inner + outer))
    x, y, h = (np.asarray(a, np.float64).tolist() for a in (x, y, h))
    verts = "".join(vertex(repr(xi), repr(-yi), f"{i * 0.5:g}", repr(-hi))
                    for i, (xi, yi, hi) in enumerate(zip(x, y, h)))
    init = teleport("A", f'<WorldPosition x="{x[0]!r}" y="{-y[0]!r}" h="{-h[0]!r}"/>').replace(
        "</Private>", follow(poly(verts), timing='<Timing domainAbsoluteRelative="absolute" '
                                                 'scale="1" offset="0"/>') + "</Private>")
    p = carla(xosc(tmp_path, ent("A"), init), "CARLA:FollowLane")
    rec, caught = run(p, map_source=town)
    got = states_of(rec)
    assert np.allclose(got["x"], x, atol=1e-6) and np.allclose(got["y"], y, atol=1e-6)
    assert np.allclose(np.angle(np.exp(1j * (got["heading"] - h))), 0.0, atol=1e-9)
    assert set(rec.states["road_id"].to_pylist()) == {"45"}
    assert set(rec.states["lane_id"].to_pylist()) == {-1}
    assert off_map(caught) == []
    _, caught = run(p, map_source=town, options={"handedness": "right"})
    (msg,) = off_map(caught)
    assert "20 of 20 vehicle states (100.0 %)" in msg and "with y negated" in msg


# --- point 3: bounding boxes of size 0 ------------------------------------------------------------

def test_zero_size_catalog_entry_takes_the_class_default(tmp_path):
    """A catalog vehicle of size 0 0 0 (as some tools write an unknown size) and an inline
    pedestrian with height 0: the class defaults with their large std, one warning per entity
    naming it (and the catalog entry); the recording passes the toolkit's own validator."""
    cat = tmp_path / "catalogs"
    cat.mkdir()
    (cat / "Vehicles.xosc").write_text(
        '<?xml version="1.0"?><OpenSCENARIO><FileHeader revMajor="1" revMinor="0" date="x" '
        'description="c" author="tool"/><Catalog name="VehicleCatalog">'
        '<Vehicle name="blank" vehicleCategory="truck"><BoundingBox><Center x="0" y="0" z="0"/>'
        '<Dimensions width="0" length="0" height="0"/></BoundingBox></Vehicle></Catalog>'
        '</OpenSCENARIO>')
    ped = ('<ScenarioObject name="P"><Pedestrian name="p" pedestrianCategory="pedestrian" mass="80">'
           '<BoundingBox><Center x="0" y="0" z="0.9"/><Dimensions width="0.6" length="0.4" '
           'height="0"/></BoundingBox></Pedestrian></ScenarioObject>')
    truck = ('<ScenarioObject name="T"><CatalogReference catalogName="VehicleCatalog" '
             'entryName="blank"/></ScenarioObject>')
    init = (teleport("T", '<WorldPosition x="20" y="-5.25" h="0"/>', 15)
            + teleport("P", '<WorldPosition x="5" y="-12" h="1.57"/>'))
    p = xosc(tmp_path, truck + ped, init,
             stop='<ConditionGroup><Condition name="e" delay="0" conditionEdge="rising">'
                  '<ByValueCondition><SimulationTimeCondition value="4" rule="greaterThan"/>'
                  '</ByValueCondition></Condition></ConditionGroup>')
    text = p.read_text().replace("<CatalogLocations/>", '<CatalogLocations><VehicleCatalog>'
                                 '<Directory path="catalogs"/></VehicleCatalog></CatalogLocations>')
    p.write_text(text)
    rec, caught = run(p)
    parts = {r["source_id"]: r for r in rec.participants.to_pylist()}
    (L, W, H), (Ls, Ws, Hs) = CLASS_SIZE["truck"]
    t = parts["T"]
    assert (t["class"], t["length"], t["width"], t["height"]) == ("truck", L, W, H)
    assert (t["length_std"], t["width_std"], t["height_std"]) == (Ls, Ws, Hs)
    assert Ls >= 0.2 * L  # large: the spread of the class, not a measurement
    pp = parts["P"]
    assert (pp["length"], pp["width"]) == (0.4, 0.6) and pp["length_std"] is None
    assert (pp["height"], pp["height_std"]) == CLASS_SIZE["pedestrian"][0][2:] + CLASS_SIZE["pedestrian"][1][2:]
    msgs = [str(w.message) for w in caught if "BoundingBox states" in str(w.message)]
    assert len(msgs) == 2
    (mt,) = [m for m in msgs if "'T'" in m]
    assert "catalog entry 'blank' of catalog 'VehicleCatalog'" in mt
    assert "length 0.0, width 0.0, height 0.0" in mt and f"length {L} ± {Ls} m" in mt
    report = aveas_format.validate(rec)
    errors = {r.code for r in report.results if r.count and r.severity.value == "error"}
    assert errors == set(), report.flatten(("code", "message"))


def test_zero_size_is_a_located_finding_of_validate(tmp_path):
    """``validate FILE`` turns it into its rule, located at the entity."""
    p = xosc(tmp_path, ent("A").replace('width="1.8" length="4.5"', 'width="0" length="0"'),
             teleport("A", '<WorldPosition x="10" y="-1.75" h="0"/>'))
    r = cli("validate", str(p), "--format", "json")
    assert "source.openscenario.zero_size" in r.stdout and "entity 'A'" in r.stdout


# --- point 4: logical scenarios ------------------------------------------------------------------

_DIST = """<?xml version="1.0"?>
<OpenSCENARIO><FileHeader revMajor="1" revMinor="2" date="2026-01-01T00:00:00" description="cut-in
variation" author="me"/>
<ParameterValueDistribution><ScenarioFile filepath="{template}"/>
{body}
</ParameterValueDistribution></OpenSCENARIO>"""

_SINGLES = """<Deterministic>
<DeterministicSingleParameterDistribution parameterName="X0">
  <DistributionSet><Element value="0"/><Element value="10"/></DistributionSet>
</DeterministicSingleParameterDistribution>
<DeterministicSingleParameterDistribution parameterName="V">
  <DistributionRange stepWidth="10"><Range lowerLimit="10" upperLimit="30"/></DistributionRange>
</DeterministicSingleParameterDistribution>
</Deterministic>"""


def _template(tmp_path):
    """A car starting at x = $X0 with speed $V (m/s), 4 s long."""
    params = ('<ParameterDeclaration name="X0" parameterType="double" value="5"/>'
              '<ParameterDeclaration name="V" parameterType="double" value="1"/>'
              '<ParameterDeclaration name="Lane" parameterType="double" value="-1.75"/>')
    return xosc(tmp_path, ent("A"), teleport("A", '<WorldPosition x="$X0" y="$Lane" h="0"/>', "$V"),
                params=params, name="cut_in.xosc",
                stop='<ConditionGroup><Condition name="e" delay="0" conditionEdge="rising">'
                     '<ByValueCondition><SimulationTimeCondition value="4" rule="greaterThan"/>'
                     '</ByValueCondition></Condition></ConditionGroup>')


def _dist(tmp_path, body=_SINGLES, template="cut_in.xosc"):
    p = tmp_path / "cut_in_variation.xosc"
    p.write_text(_DIST.format(template=template, body=body))
    return p


def test_logical_scenario_is_named_with_its_template(tmp_path):
    """Not ``no <Storyboard>``: the file, what it is, the template it varies, how many concrete
    variations it has and how to import one."""
    _template(tmp_path)
    p = _dist(tmp_path)
    with pytest.raises(FormatError) as e:
        run(p)
    msg = str(e.value)
    assert str(p) in msg and "logical scenario" in msg and "parameter variation" in msg
    assert "template scenario 'cut_in.xosc'" in msg and str(tmp_path / "cut_in.xosc") in msg
    assert "6 concrete variations with -O variation=N (N = 0..5)" in msg
    # the template missing: said too
    with pytest.raises(FormatError, match="'gone.xosc' .not found at"):
        run(_dist(tmp_path, template="gone.xosc"))
    # through the CLI: one line, exit 3
    r = cli("convert", "--from", "openscenario", str(p), "-o", str(tmp_path / "o.aveas"))
    assert r.returncode == 3 and "logical scenario" in r.stderr and "Traceback" not in r.stderr


def test_one_variation_is_the_template_with_its_values(tmp_path):
    """Variation N of two single-parameter distributions (2 x 3 values, the last varying
    fastest): N = 4 is X0 = 10 (second of 0, 10), V = 20 (second of 10, 20, 30)."""
    _template(tmp_path)
    p = _dist(tmp_path)
    for n, x0, v in ((0, 0, 10), (4, 10, 20), (5, 10, 30)):
        rec, _ = run(p, options={"variation": n})
        s = states_of(rec)
        assert s["x"][0] == pytest.approx(x0)
        assert s["x"][-1] - s["x"][0] == pytest.approx(v * 4.0)  # 4 s at V m/s
        var = rec.meta.extras["openscenario"]["variation"]
        assert var == {"file": p.name, "template": "cut_in.xosc", "index": n, "of": 6,
                       "parameters": {"X0": str(x0), "V": str(v)}}
        assert [i.file for i in rec.meta.source.inputs] == [p.name, "cut_in.xosc"]
    # the user's own parameter value wins over the variation's
    rec, _ = run(p, options={"variation": 4, "parameter": {"V": 5}})
    assert np.ptp(states_of(rec)["x"]) == pytest.approx(20.0)
    with pytest.raises(FormatError, match=r"variation 6: the file has 6 concrete variations"):
        run(p, options={"variation": 6})
    r = cli("convert", "--from", "openscenario", str(p), "-O", "variation=4", "-O", "license=CC0-1.0",
            "-o", str(tmp_path / "v4.aveas"))
    assert r.returncode == 0, r.stderr


def test_value_sets_stochastic_and_bad_distributions(tmp_path):
    """A multi-parameter value set combines with a single distribution; a stochastic
    distribution is said to be not expanded; a parameter the template does not declare, and a
    range without a positive step, are errors naming the file (and line)."""
    _template(tmp_path)
    body = """<Deterministic><DeterministicMultiParameterDistribution><ValueSetDistribution>
<ParameterValueSet><ParameterAssignment parameterRef="X0" value="1"/><ParameterAssignment parameterRef="Lane" value="-5.25"/></ParameterValueSet>
<ParameterValueSet><ParameterAssignment parameterRef="X0" value="2"/><ParameterAssignment parameterRef="Lane" value="-8.75"/></ParameterValueSet>
</ValueSetDistribution></DeterministicMultiParameterDistribution></Deterministic>
<Stochastic numberOfTestRuns="10" randomSeed="1"><StochasticDistribution parameterName="V">
<NormalDistribution expectedValue="20" variance="4"/></StochasticDistribution></Stochastic>"""
    p = _dist(tmp_path, body)
    rec, caught = run(p, options={"variation": 1})
    s = states_of(rec)
    assert s["x"][0] == pytest.approx(2.0) and np.allclose(s["y"], -8.75)
    assert np.ptp(s["x"]) == pytest.approx(4.0)  # V keeps the template's 1 m/s
    (note,) = [str(w.message) for w in caught if "stochastic" in str(w.message)]
    assert "V keep the template's declared values" in note.replace("parameter V", "V")
    bad = _dist(tmp_path, _SINGLES.replace('"V"', '"Speed"'))
    with pytest.raises(FormatError, match="parameter 'Speed' of the parameter variation is not "
                                          "declared by the template scenario cut_in.xosc"):
        run(bad, options={"variation": 0})
    bad = _dist(tmp_path, _SINGLES.replace('stepWidth="10"', 'stepWidth="0"'))
    with pytest.raises(FormatError, match=r"stepWidth 0.0 over 10.0..30.0: the step must be "
                                          r"positive") as e:
        run(bad, options={"variation": 0})
    assert e.value.where["line"] == 10


def test_catalog_or_non_scenario_files_say_what_they_are(tmp_path):
    cat = tmp_path / "Vehicles.xosc"
    cat.write_text('<?xml version="1.0"?><OpenSCENARIO><FileHeader revMajor="1" revMinor="0" '
                   'date="x" description="c" author="me"/><Catalog name="VehicleCatalog"/>'
                   '</OpenSCENARIO>')
    with pytest.raises(FormatError, match="a catalog .catalog 'VehicleCatalog'., not a scenario"):
        run(cat, map_source=STRAIGHT_MAP)
    p = xosc(tmp_path, ent("A"), teleport("A", '<WorldPosition x="10" y="-1.75" h="0"/>'))
    with pytest.raises(FormatError, match="not a parameter variation file"):
        run(p, options={"variation": 0})
