"""The OpenSCENARIO import as scenario tools write it (issue 18, point 2): one small file per
feature, on the hand-made straight map (x along the road, lanes -1..-3 of 3.5 m at y = -1.75,
-5.25, -8.75), plus esmini's own clothoid lane change (tests/data/third_party/esmini, MPL-2.0)."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

import aveas_format
from aveas_format.converters.openscenario.params import evaluate
from aveas_format.converters.registry import convert
from aveas_format.errors import FormatError
from helpers_common import DATA
from helpers_xosc import ent, event, follow, poly, sim_time, states_of, story, teleport, vertex, xosc

ESMINI = DATA / "third_party" / "esmini"


def run(path, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rec = convert("openscenario", [path], **kw)
    return rec, [str(x.message) for x in w if issubclass(x.category, UserWarning)
                 and "GeoReference" not in type(x.message).__name__]


# --- parameters, expressions -----------------------------------------------------------------------

def test_expressions_are_evaluated_safely():
    assert evaluate("$a + 2 * $b", {"a": "1", "b": "3.5"}) == 8.0
    assert evaluate("-pi / 2", {}) == pytest.approx(-math.pi / 2)
    assert evaluate("round(2.5) + pow(2, 3) + sqrt(16)", {}) == 15.0
    assert evaluate("$a > 1 and not $b == 3", {"a": "2", "b": "4"}) == 1.0
    for bad in ("__import__('os')", "a.b", "2 ** 2", "[1][0]", "open('x')"):
        with pytest.raises(FormatError):
            evaluate(bad, {})
    with pytest.raises(FormatError, match=r"\$nope is not declared"):
        evaluate("$nope + 1", {})


def test_parameters_expressions_and_overrides(tmp_path):
    params = ('<ParameterDeclaration name="X0" parameterType="double" value="10"/>'
              '<ParameterDeclaration name="V" parameterType="double" value="36"/>'
              '<ParameterDeclaration name="X1" parameterType="double" value="${$X0 + 90}"/>')
    init = (teleport("A", '<WorldPosition x="$X0" y="-1.75" h="0"/>', "${$V / 3.6}")
            .replace("</Private>", follow(poly(vertex("$X0", -1.75), vertex("$X1", -1.75))) + "</Private>"))
    p = xosc(tmp_path, ent("A"), init, params=params)
    rec, _ = run(p)
    s = states_of(rec)
    assert s["x"][0] == pytest.approx(10.0) and s["x"][-1] == pytest.approx(100.0)
    assert s["time"][-1] == pytest.approx(9.0)  # 90 m at 10 m/s
    rec2, _ = run(p, options={"parameter": {"V": 72, "X0": 0}})
    s2 = states_of(rec2)
    assert s2["x"][0] == pytest.approx(0.0) and s2["time"][-1] == pytest.approx(4.5)  # 90 m at 20 m/s
    with pytest.raises(FormatError, match="parameter 'Nope'.*not declared"):
        run(p, options={"parameter": {"Nope": 1}})


def test_cli_parameter_override(tmp_path):
    init = teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>', "$V").replace(
        "</Private>", follow(poly(vertex(0, -1.75), vertex(100, -1.75))) + "</Private>")
    p = xosc(tmp_path, ent("A"), init,
             params='<ParameterDeclaration name="V" parameterType="double" value="10"/>')
    out = tmp_path / "o.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "openscenario",
                          str(p), "-O", "parameter.V=25", "-O", "license=CC0-1.0", "-o", str(out), "--no-validate"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert aveas_format.open(out).meta.duration_s == pytest.approx(4.0)


# --- entities and catalogs ------------------------------------------------------------------------

def test_catalog_reference_with_parameter_assignments(tmp_path):
    cat = tmp_path / "cat"
    cat.mkdir()
    (cat / "Vehicles.xosc").write_text("""<OpenSCENARIO><FileHeader revMajor="1" revMinor="2" date="x"
description="c" author="me"/><Catalog name="VehicleCatalog">
<Vehicle name="bus" vehicleCategory="bus"><ParameterDeclarations>
<ParameterDeclaration name="L" parameterType="double" value="12"/></ParameterDeclarations>
<BoundingBox><Center x="2" y="0" z="1.5"/><Dimensions width="2.5" length="$L" height="3"/></BoundingBox>
</Vehicle></Catalog></OpenSCENARIO>""")
    ents = ('<ScenarioObject name="A"><CatalogReference catalogName="VehicleCatalog" entryName="bus">'
            '<ParameterAssignments><ParameterAssignment parameterRef="L" value="18"/>'
            '</ParameterAssignments></CatalogReference></ScenarioObject>'
            '<ScenarioObject name="B"><CatalogReference catalogName="VehicleCatalog" entryName="bus"/>'
            '</ScenarioObject>'
            '<ScenarioObject name="C"><CatalogReference catalogName="VehicleCatalog" entryName="tram"/>'
            '</ScenarioObject>')
    init = "".join(teleport(n, f'<WorldPosition x="{x}" y="-5.25" h="0"/>')
                   for n, x in (("A", 10), ("B", 50), ("C", 90)))
    p = xosc(tmp_path, ents, init)
    p.write_text(p.read_text().replace("<CatalogLocations/>", '<CatalogLocations><VehicleCatalog>'
                                       '<Directory path="cat"/></VehicleCatalog></CatalogLocations>'))
    rec, warned = run(p)
    parts = rec.participants.to_pylist()
    assert [(r["source_id"], r["class"], r["length"]) for r in parts] == [("A", "bus", 18.0),
                                                                          ("B", "bus", 12.0)]
    # the reference point is 2 m behind the bounding box centre: positions are the centre's
    assert states_of(rec)["x"][0] == pytest.approx(12.0)
    # C cannot be converted: one warning line naming it, where and why
    assert [w for w in warned if "'C'" in w] == [
        f"{p}:5: entity 'C' not converted: catalog entry 'tram' of catalog 'VehicleCatalog' not "
        "found in the CatalogLocations"]


def test_no_entity_convertible_is_an_error(tmp_path):
    init = teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>').replace(
        "</Private>", follow(poly(vertex(0, -1.75), vertex(50, -1.75))) + "</Private>")
    p = xosc(tmp_path, ent("A"), init)
    with pytest.raises(FormatError, match=r"s\.xosc: no participants: .*'A': its trajectory 'tr' has "
                                          r"no vertex times .* speed is 0"):
        run(p)


# --- timing ---------------------------------------------------------------------------------------

def test_untimed_vertices_timed_by_speed_and_initial_offset(tmp_path):
    init = teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>', -5).replace(
        "</Private>", follow(poly(vertex(0, -1.75), vertex(30, -1.75), vertex(30, -5.25)),
                             extra='initialDistanceOffset="30"') + "</Private>")
    rec, _ = run(xosc(tmp_path, ent("A"), init))
    s = states_of(rec)
    # negative speed: backwards along the path from 30 m to 0 m, 6 s
    assert s["time"][-1] == pytest.approx(6.0)
    assert s["x"][0] == pytest.approx(30.0) and s["x"][-1] == pytest.approx(0.0)
    assert np.all(np.diff(s["x"]) <= 1e-9)


def test_timed_vertices_relative_scale_offset(tmp_path):
    timing = '<Timing domainAbsoluteRelative="relative" scale="2" offset="1"/>'
    ev = event("go", follow(poly(vertex(0, -1.75, 0), vertex(20, -1.75, 1), vertex(40, -1.75, 2)), timing),
               sim_time(3))
    init = teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>')
    rec, _ = run(xosc(tmp_path, ent("A"), init, story(ev)))
    s = states_of(rec)
    # starts at 3 s; vertex times 0, 1, 2 -> 3 + 1 + 2 t
    np.testing.assert_allclose(s["time"], [4.0, 6.0, 8.0])
    np.testing.assert_allclose(s["x"], [0.0, 20.0, 40.0])


# --- triggers, chained events, entity conditions ----------------------------------------------------

def test_triggers_chain_and_entity_conditions(tmp_path):
    # A drives at 10 m/s along lane -1 from x=0; B starts its trajectory when A reaches x=50
    # (ReachPositionCondition), then a second one when the first is complete (+1 s delay)
    reach = ('<Condition name="r" delay="0" conditionEdge="rising"><ByEntityCondition>'
             '<TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="A"/>'
             '</TriggeringEntities><EntityCondition><ReachPositionCondition tolerance="0.3">'
             '<Position><WorldPosition x="50" y="-1.75"/></Position></ReachPositionCondition>'
             '</EntityCondition></ByEntityCondition></Condition>')
    after = ('<Condition name="a" delay="1" conditionEdge="rising"><ByValueCondition>'
             '<StoryboardElementStateCondition storyboardElementType="event" '
             'storyboardElementRef="first" state="endTransition"/></ByValueCondition></Condition>')
    speed = ('<PrivateAction><LongitudinalAction><SpeedAction><SpeedActionDynamics '
             'dynamicsShape="step" dynamicsDimension="time" value="0"/><SpeedActionTarget>'
             '<AbsoluteTargetSpeed value="20"/></SpeedActionTarget></SpeedAction>'
             '</LongitudinalAction></PrivateAction>')
    evs = (event("first", [speed, follow(poly(vertex(100, -5.25), vertex(120, -5.25)))], reach)
           + event("second", follow(poly(vertex(120, -5.25), vertex(140, -8.75))), after))
    init = (teleport("A", '<LanePosition roadId="1" laneId="-1" s="0" offset="0"/>', 10)
            + teleport("B", '<WorldPosition x="100" y="-5.25" h="0"/>'))
    stop = ('<ConditionGroup>' + sim_time(20) + '</ConditionGroup>')
    rec, warned = run(xosc(tmp_path, ent("A") + ent("B"), init, story(evs, "B"), stop=stop))
    a, b = states_of(rec, 0), states_of(rec, 1)
    assert a["time"][-1] == pytest.approx(20.0) and a["x"][-1] == pytest.approx(200.0, abs=0.05)
    assert np.allclose(a["y"], -1.75)  # lane following
    t_first = b["time"][np.flatnonzero(b["x"] > 100.0 + 1e-6)[0] - 1]
    assert t_first == pytest.approx(5.0, abs=0.06)  # A at x = 50 after 5 s
    # first trajectory 20 m at 20 m/s: ends at 6 s; the second starts 1 s later
    i_second = np.flatnonzero(b["y"] < -5.25 - 1e-6)[0]
    assert b["time"][i_second - 1] == pytest.approx(7.0, abs=0.06)
    t_end = 7.0 + math.hypot(20, 3.5) / 20
    k = int(np.argmin(np.abs(b["time"] - t_end)))
    assert b["time"][k] == pytest.approx(t_end, abs=0.06)  # an extra step where it ends
    assert (b["x"][k], b["y"][k]) == pytest.approx((140.0, -8.75), abs=0.01)
    # then on along its lane at its speed (untimed: the speed goes on)
    assert np.allclose(b["y"][k:], -8.75) and b["x"][-1] - b["x"][k] == pytest.approx(
        20 * (20.0 - b["time"][k]), abs=0.5)
    assert not any("not converted" in w for w in warned)


def test_not_replayed_actions_are_named(tmp_path):
    lo = ('<PrivateAction><LateralAction><LaneOffsetAction continuous="false">'
          '<LaneOffsetActionDynamics dynamicsShape="linear" maxLateralAcc="0.5"/><LaneOffsetTarget>'
          '<AbsoluteTargetLaneOffset value="0.5"/></LaneOffsetTarget></LaneOffsetAction>'
          '</LateralAction></PrivateAction>')
    init = teleport("A", '<LanePosition roadId="1" laneId="-2" s="0" offset="0"/>', 10)
    rec, warned = run(xosc(tmp_path, ent("A"), init, story(event("lo", lo)),
                           stop="<ConditionGroup>" + sim_time(3) + "</ConditionGroup>"))
    assert any("not replayed: LaneOffsetAction" in w for w in warned), warned
    assert rec.meta.extras["openscenario"]["actions_not_replayed"] == {"LaneOffsetAction": 1}


# --- positions and shapes -------------------------------------------------------------------------

def test_lane_road_and_relative_positions(tmp_path):
    ents = ent("A") + ent("B") + ent("C") + ent("D")
    init = (teleport("A", '<LanePosition roadId="1" laneId="-2" s="40" offset="0.5"/>')
            + teleport("B", '<RelativeLanePosition entityRef="A" dLane="-1" ds="10" offset="0"/>')
            + teleport("C", '<RelativeObjectPosition entityRef="A" dx="-8" dy="2"/>')
            + teleport("D", '<RoadPosition roadId="1" s="70" t="-1"/>'))
    rec, _ = run(xosc(tmp_path, ents, init))
    xy = [(states_of(rec, k)["x"][0], states_of(rec, k)["y"][0]) for k in range(4)]
    np.testing.assert_allclose(xy, [(40.0, -4.75), (50.0, -8.75), (32.0, -2.75), (70.0, -1.0)],
                               atol=1e-9)


def test_clothoid_is_an_arc_of_the_given_curvature(tmp_path):
    k, L = 0.02, 50.0
    shape = ('<Clothoid curvature="0.02" curvaturePrime="0" length="50" startTime="0" stopTime="5">'
             '<Position><WorldPosition x="10" y="-5.25" h="0"/></Position></Clothoid>')
    timing = '<Timing domainAbsoluteRelative="relative" scale="1" offset="0"/>'
    init = teleport("A", '<WorldPosition x="10" y="-5.25" h="0"/>').replace(
        "</Private>", follow(shape, timing) + "</Private>")
    rec, _ = run(xosc(tmp_path, ent("A"), init))
    s = states_of(rec)
    assert s["time"][-1] == pytest.approx(5.0)
    # closed form of a circular arc from (10, -5.25) heading 0
    assert s["x"][-1] == pytest.approx(10 + math.sin(k * L) / k, abs=2e-3)
    assert s["y"][-1] == pytest.approx(-5.25 + (1 - math.cos(k * L)) / k, abs=2e-3)
    assert s["heading"][-1] == pytest.approx(k * L, abs=1e-3)


def test_nurbs_order_2_is_the_control_polygon_and_times_interpolate(tmp_path):
    cps = "".join(f'<ControlPoint time="{t}" weight="1"><Position><WorldPosition x="{x}" y="{y}"/>'
                  f"</Position></ControlPoint>" for t, x, y in ((0, 0, -1.75), (2, 40, -1.75),
                                                                 (4, 40, -8.75)))
    knots = "".join(f'<Knot value="{v}"/>' for v in (0, 0, 0.5, 1, 1))
    shape = f'<Nurbs order="2">{cps}{knots}</Nurbs>'
    timing = '<Timing domainAbsoluteRelative="absolute" scale="1" offset="0"/>'
    init = teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>').replace(
        "</Private>", follow(shape, timing) + "</Private>")
    rec, _ = run(xosc(tmp_path, ent("A"), init))
    s = states_of(rec)
    assert s["time"][0] == pytest.approx(0.0) and s["time"][-1] == pytest.approx(4.0)
    i = np.argmin(np.abs(s["time"] - 2.0))
    assert (s["x"][i], s["y"][i]) == pytest.approx((40.0, -1.75), abs=0.5)
    # on the polygon: y = -1.75 while x < 40, x = 40 after
    assert np.all((np.abs(s["y"] + 1.75) < 1e-6) | (np.abs(s["x"] - 40) < 1e-6))
    bad = shape.replace('<Knot value="0.5"/>', "")
    init2 = init.replace(shape, bad)
    with pytest.raises(FormatError, match="needs 5 knots, has 4"):
        run(xosc(tmp_path, ent("A"), init2, name="bad.xosc"))


def test_geo_position_needs_a_crs(tmp_path):
    init = teleport("A", '<GeoPosition latitudeDeg="48.9" longitudeDeg="8.3505"/>')
    rec, _ = run(xosc(tmp_path, ent("A"), init))
    assert states_of(rec)["x"][0] == pytest.approx(36.6, abs=0.2)  # 0.0005 deg east at 48.9 N


# --- a scenario tool's own file --------------------------------------------------------------------

def test_esmini_clothoid_lane_change(tmp_path):
    """esmini's lane change of three clothoids (arc, line, arc) relative to the car, chained by
    completeState, at the catalog car's speed ${$Speed / 3.6}; its map has a geoReference."""
    d = tmp_path / "esmini"
    shutil.copytree(ESMINI, d)
    rec, warned = run(d / "xosc" / "lane-change_clothoid_based_trajectory.xosc")
    assert not [w for w in warned if "not converted" in w]
    s = states_of(rec)
    v = 50 / 3.6
    # 2 s on the lane, then 15 + 5 + 15 m of clothoids at 50 km/h
    assert rec.meta.duration_s == pytest.approx(2.0 + 35.0 / v, abs=0.06)
    assert rec.participants.to_pylist()[0]["length"] == pytest.approx(5.04)  # from the catalog
    # the lateral shift of arc + line + arc (radius 100 m): 2 (1 - cos 0.15) 100 + 5 sin 0.15
    shift = 2 * 100 * (1 - math.cos(0.15)) + 5 * math.sin(0.15)
    assert s["y"][-1] - s["y"][0] == pytest.approx(shift, abs=0.02)
    assert s["heading"][-1] == pytest.approx(0.0, abs=1e-3)
    report = aveas_format.validate(rec)
    assert report.counts["error"] == 0, [f.message for f in report.findings() if f.severity.value == "error"]


def test_maneuver_and_trajectory_catalogs(tmp_path):
    """A ManeuverGroup's maneuver and a FollowTrajectoryAction's trajectory from catalogs, each with
    its parameters assigned by the reference."""
    cat = tmp_path / "cat"
    cat.mkdir()
    (cat / "Trajectories.xosc").write_text("""<OpenSCENARIO><FileHeader revMajor="1" revMinor="2"
date="x" description="c" author="me"/><Catalog name="TrajectoryCatalog">
<Trajectory name="straight" closed="false"><ParameterDeclarations>
<ParameterDeclaration name="X1" parameterType="double" value="50"/></ParameterDeclarations>
<Shape><Polyline><Vertex><Position><WorldPosition x="0" y="-1.75"/></Position></Vertex>
<Vertex><Position><WorldPosition x="$X1" y="-1.75"/></Position></Vertex></Polyline></Shape>
</Trajectory></Catalog></OpenSCENARIO>""")
    (cat / "Maneuvers.xosc").write_text("""<OpenSCENARIO><FileHeader revMajor="1" revMinor="2"
date="x" description="c" author="me"/><Catalog name="ManeuverCatalog">
<Maneuver name="drive"><ParameterDeclarations>
<ParameterDeclaration name="Len" parameterType="double" value="50"/></ParameterDeclarations>
<Event name="go" priority="override"><Action name="go_a"><PrivateAction><RoutingAction>
<FollowTrajectoryAction><TrajectoryRef><CatalogReference catalogName="TrajectoryCatalog"
entryName="straight"><ParameterAssignments><ParameterAssignment parameterRef="X1" value="$Len"/>
</ParameterAssignments></CatalogReference></TrajectoryRef><TimeReference><None/></TimeReference>
<TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction></RoutingAction>
</PrivateAction></Action></Event></Maneuver></Catalog></OpenSCENARIO>""")
    st = ('<Story name="s"><Act name="act"><ManeuverGroup maximumExecutionCount="1" name="mg">'
          '<Actors selectTriggeringEntities="false"><EntityRef entityRef="A"/></Actors>'
          '<CatalogReference catalogName="ManeuverCatalog" entryName="drive"><ParameterAssignments>'
          '<ParameterAssignment parameterRef="Len" value="80"/></ParameterAssignments>'
          '</CatalogReference></ManeuverGroup></Act></Story>')
    p = xosc(tmp_path, ent("A"), teleport("A", '<WorldPosition x="0" y="-1.75" h="0"/>', 10), st)
    p.write_text(p.read_text().replace("<CatalogLocations/>", (
        "<CatalogLocations><ManeuverCatalog><Directory path=\"cat\"/></ManeuverCatalog>"
        "<TrajectoryCatalog><Directory path=\"cat\"/></TrajectoryCatalog></CatalogLocations>")))
    rec, warned = run(p)
    s = states_of(rec)
    assert s["x"][-1] == pytest.approx(80.0) and rec.meta.duration_s == pytest.approx(8.0)


def test_clothoid_spline_segments_hoffset_position_start_and_times(tmp_path):
    """ClothoidSpline (1.3) as esmini's lane-change_clothoid_spline_based_trajectory.xosc uses it:
    an arc, a line and an arc continuing each other; a later segment restarting at its own
    PositionStart; hOffset turning a segment's start; timeStart/timeEnd timing the segments."""
    seg = '<ClothoidSplineSegment curvatureStart="{k}" curvatureEnd="{k}" length="{L}"{extra}>{ps}</ClothoidSplineSegment>'
    ps = ('<PositionStart><WorldPosition x="{x}" y="{y}" h="0"/></PositionStart>')
    shape = ('<ClothoidSpline timeEnd="6">'
             + seg.format(k=0.01, L=15, extra=' timeStart="0"', ps=ps.format(x=10, y=-5.25))
             + seg.format(k=0.0, L=5, extra=' timeStart="2"', ps="")
             + seg.format(k=0.0, L=10, extra=' timeStart="3" hOffset="-0.15"',
                          ps=ps.format(x=40, y=-1.75))
             + "</ClothoidSpline>")
    timing = '<Timing domainAbsoluteRelative="relative" scale="1" offset="0"/>'
    init = teleport("A", '<WorldPosition x="10" y="-5.25" h="0"/>').replace(
        "</Private>", follow(shape, timing) + "</Private>")
    rec, _ = run(xosc(tmp_path, ent("A"), init))
    s = states_of(rec)
    assert s["time"][-1] == pytest.approx(6.0)
    # arc of radius 100 over 15 m then 5 m straight: heading 0.15 there
    i2 = int(np.argmin(np.abs(s["time"] - 2.0)))
    assert s["heading"][i2] == pytest.approx(0.15, abs=0.01)
    assert s["x"][i2] == pytest.approx(10 + 100 * math.sin(0.15), abs=0.05)
    # the third segment restarts at (40, -1.75) with heading 0 - 0.15 and runs 10 m straight
    assert (s["x"][-1], s["y"][-1]) == pytest.approx((40 + 10 * math.cos(0.15), -1.75 - 10 * math.sin(0.15)),
                                                     abs=0.01)
    assert s["heading"][-1] == pytest.approx(-0.15, abs=1e-6)


def test_end_of_road_stop_trigger_and_closed_polyline(tmp_path):
    """An EndOfRoadCondition ends the replay (A drives off the end of the 1000 m road at 50 m/s:
    20 s, + 1 s duration); B drives a closed square, back to its first vertex."""
    eor = ('<ConditionGroup><Condition name="eor" delay="0" conditionEdge="rising"><ByEntityCondition>'
           '<TriggeringEntities triggeringEntitiesRule="any"><EntityRef entityRef="A"/>'
           '</TriggeringEntities><EntityCondition><EndOfRoadCondition duration="1"/></EntityCondition>'
           '</ByEntityCondition></Condition></ConditionGroup>')
    sq = poly(vertex(100, -2), vertex(110, -2), vertex(110, -8), vertex(100, -8))
    init = (teleport("A", '<LanePosition roadId="1" laneId="-1" s="0" offset="0"/>', 50)
            + teleport("B", '<WorldPosition x="100" y="-2" h="0"/>', 2).replace(
                "</Private>", follow(sq).replace('closed="false"', 'closed="true"') + "</Private>"))
    rec, _ = run(xosc(tmp_path, ent("A") + ent("B"), init, stop=eor))
    assert rec.meta.duration_s == pytest.approx(21.0, abs=0.06)
    b = states_of(rec, 1)
    k = int(np.argmin(np.abs(b["time"] - 16.0)))  # 32 m around the square at 2 m/s
    assert (b["x"][k], b["y"][k]) == pytest.approx((100.0, -2.0), abs=0.01)


def test_lane_change_action(tmp_path):
    """A cut-in: B changes from lane -2 to the lane left of it (-1) over 3 s, sinusoidal, while
    following its lane at 20 m/s; heading turns with the sideways motion; the recording is valid."""
    lc = ('<PrivateAction><LateralAction><LaneChangeAction><LaneChangeActionDynamics '
          'dynamicsShape="sinusoidal" value="3" dynamicsDimension="time"/><LaneChangeTarget>'
          '<RelativeTargetLane entityRef="B" value="1"/></LaneChangeTarget></LaneChangeAction>'
          '</LateralAction></PrivateAction>')
    init = teleport("B", '<LanePosition roadId="1" laneId="-2" s="10" offset="0"/>', 20)
    stop = "<ConditionGroup>" + sim_time(8) + "</ConditionGroup>"
    rec, warned = run(xosc(tmp_path, ent("B"), init, story(event("lc", lc, sim_time(2)), "B"), stop=stop))
    assert not any("not replayed" in w for w in warned)
    b = states_of(rec)
    y_at = lambda t: b["y"][int(np.argmin(np.abs(b["time"] - t)))]  # noqa: E731
    assert y_at(1.9) == pytest.approx(-5.25) and y_at(5.1) == pytest.approx(-1.75)
    assert y_at(3.5) == pytest.approx(-3.5, abs=0.01)  # half way at half time (sinusoidal)
    h_mid = b["heading"][int(np.argmin(np.abs(b["time"] - 3.5)))]
    assert h_mid == pytest.approx(math.atan2(3.5 * math.pi / 6, 20), abs=0.01)  # peak lateral speed
    assert aveas_format.validate(rec).counts["error"] == 0
