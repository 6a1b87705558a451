"""``aveas-format validate FILE`` on what partners submit (issue 22): a file of any importable
format is imported on the fly and its import's findings are rules of their own (``source.*``),
located in the source's own terms — OpenLABEL frame key / object uid / JSON path, OSI message index
/ object id, OpenSCENARIO entity / XML line — with a count.

OpenLABEL: the reader's located findings are being written on another branch (issue 22a), so the
``source.openlabel.*`` rules are tested here at the rule level with collected findings, and end to
end only on what does not depend on that change (a box with a -1000 size is reported by the import,
under ``source.openlabel.bad_size`` once the reader locates it, until then as ``source.other``).
OSI and OpenSCENARIO: end to end on crafted files.
"""

from __future__ import annotations

import json
import struct
import warnings

import numpy as np
import pytest

import aveas_format
from aveas_format.cli.app import app
from aveas_format.cli.common import run
from aveas_format.converters.registry import convert
from aveas_format.errors import SourceFinding, collect_source_findings, report_source
from aveas_format.validate import REGISTRY, load_rules
from aveas_format.validate.report import Report
from aveas_format.validate.rules.source import SOURCE_RULES
from helpers_common import STRAIGHT_MAP, small_recording

OPENLABEL_CODES = ("bad_size", "duplicate_state", "unknown_type", "pmf_sum", "missing_attribute",
                   "unknown_coordinate_system", "bad_metadata", "extension_skipped")


def cli(capsys, *args):
    code = run(app, [str(a) for a in args])
    res = capsys.readouterr()
    return code, res.out, res.err


def source_results(report: Report) -> dict:
    return {r.code: r for r in report.results if r.code.startswith("source.")}


# --- the rules ------------------------------------------------------------------------------------

def test_every_source_code_is_a_documented_rule():
    load_rules()
    codes = {s.code for s in SOURCE_RULES}
    assert {f"source.openlabel.{c}" for c in OPENLABEL_CODES} <= codes
    for code in codes:
        r = REGISTRY[code]
        assert r.doc and r.title and r.family == "source"
    # a group selects its rules
    from aveas_format.validate import select_rules

    assert {r.code for r in select_rules(["source.osi"])} == {c for c in codes
                                                            if c.startswith("source.osi.")}


@pytest.mark.parametrize("spec", SOURCE_RULES, ids=[s.code for s in SOURCE_RULES])
def test_each_source_rule_reports_exactly_its_findings(spec):
    """Every source.* rule's failing case: a collected finding of its code (and one of another
    code, which it must not report) -> one finding of that rule, at the given location, with the
    count; its passing case is a recording without source findings (test below)."""
    other = "source.osi.missing_base" if spec.code != "source.osi.missing_base" else \
        "source.osi.unknown_type"
    code = "source.partner.custom" if spec.code == "source.other" else spec.code
    found = [SourceFinding(code, "what is wrong", {"file": "f", "line": 3, "entity": "E",
                                                   "message_index": 2}, count=4),
             SourceFinding(other, "another finding", {"file": "f"})]
    rep = aveas_format.validate(small_recording(), select=[spec.code], source_findings=found)
    (r,) = rep.results
    assert (r.code, r.count, r.severity.value) == (spec.code, 4, spec.severity)
    loc = r.sample[0].location
    assert (loc.file, loc.line, loc.entity, loc.message_index) == ("f", 3, "E", 2)


def test_collected_openlabel_findings_become_located_findings_with_counts():
    """The rule level: findings as the OpenLABEL reader reports them (frame key, uid, JSON path,
    count) come out typed, counted, rendered and round-tripped; a code without a rule of its own
    is kept under source.other."""
    found = [
        SourceFinding("source.openlabel.bad_size", "3 boxes with size -1000 dropped",
                      {"file": "sub.json", "frame": "12", "uid": "7",
                       "json_path": "$.openlabel.frames['12'].objects['7'].object_data.cuboid[0]"},
                      count=3),
        SourceFinding("source.openlabel.missing_attribute", "object 9 has no type",
                      {"file": "sub.json", "uid": "9", "json_path": "$.openlabel.objects['9']"}),
        SourceFinding("source.openlabel.pmf_sum", "class PMF sums to 0.8",
                      {"file": "sub.json", "frame": "0", "uid": "4"}, count=2),
        SourceFinding("source.plugin.thing", "a plugin's finding", {"file": "sub.json"}),
    ]
    rep = aveas_format.validate(small_recording(), select=["source"], source_findings=found,
                                name="sub.json")
    res = source_results(rep)
    assert res["source.openlabel.bad_size"].count == 3
    assert res["source.openlabel.pmf_sum"].count == 2
    assert res["source.openlabel.missing_attribute"].count == 1
    f = res["source.openlabel.bad_size"].sample[0]
    assert (f.location.frame, f.location.uid, f.count) == ("12", "7", 3)
    assert f.location.json_path.endswith("cuboid[0]")
    assert f.message == "3 boxes with size -1000 dropped"  # no location inside the message
    assert "frame=12 uid=7" in f.location.text()
    other = res["source.other"].sample[0]
    assert other.context == {"source_message": "a plugin's finding", "source_code": "source.plugin.thing"}
    assert rep.recording == "sub.json" and rep.exit_code == 1  # bad_size is an error
    back = Report.from_json(rep.to_json())
    assert back == rep
    assert back.findings()[0].location.frame == "12"
    # the HTML report shows the source's own columns
    from aveas_format.plot.report_html import render_html

    assert "<th>frame</th>" in render_html(rep, None)


def test_a_recording_has_no_source_findings():
    rep = aveas_format.validate(small_recording(), select=["source"])
    assert rep.codes == set()


def test_report_source_warns_with_its_location_when_nobody_collects():
    with pytest.warns(UserWarning, match=r"^t\.osi: message index 3, object id 7: no dimension$"):
        report_source("source.osi.missing_dimension", "no dimension", file="t.osi",
                      message_index=3, object_id=7)
    with collect_source_findings() as found, warnings.catch_warnings():
        warnings.simplefilter("error")
        report_source("source.osi.missing_dimension", "no dimension", message_index=3)
    assert found == [SourceFinding("source.osi.missing_dimension", "no dimension",
                                   {"message_index": 3})]


# --- OpenLABEL end to end ---------------------------------------------------------------------------

def openlabel_submission(tmp_path, bad_frames=(5, 6)):
    frames = {}
    for k in range(20):
        size = [-1000, -1000, -1000] if k in bad_frames else [4.5, 1.8, 1.5]
        frames[str(k)] = {"frame_properties": {"timestamp": 0.1 * k}, "objects": {"7": {
            "object_data": {"cuboid": [{"name": "box", "val": [10 + 2 * k, -1.75, 0.75, 0, 0, 0,
                                                                *size]}]}}}}
    doc = {"openlabel": {"metadata": {"schema_version": "1.0.0"},
                         "objects": {"7": {"name": "car7", "type": "Car"}}, "frames": frames}}
    p = tmp_path / "submission.json"
    p.write_text(json.dumps(doc))
    return p


def test_openlabel_submission_reports_the_dropped_boxes(capsys, tmp_path):
    """End to end, independent of the reader's rewrite: the import's finding about the -1000 boxes
    is in the report (located by the reader: source.openlabel.bad_size; until then: source.other
    naming the file), next to the format's rules, and the states of those frames are not there."""
    p = openlabel_submission(tmp_path)
    code, out, err = cli(capsys, "validate", p, "--map", STRAIGHT_MAP, "--format", "json")
    rep = Report.from_json(out)
    res = source_results(rep)
    assert code == rep.exit_code() and rep.recording == str(p)
    if "source.openlabel.bad_size" in res:
        f = res["source.openlabel.bad_size"].sample[0]
        assert f.location.uid == "7" and f.location.frame == "5"
        assert res["source.openlabel.bad_size"].count == 2 and code == 1
    else:
        f = res["source.other"].sample[0]
        assert f.location.file == str(p) and "sentinel or impossible size" in f.message
    assert "kinematics.speed" in rep.rules_run  # the format's rules ran on the import


# --- OSI end to end --------------------------------------------------------------------------------

b = pytest.importorskip("betterosi")


def osi_trace(path, n=20):
    """Object 1: no dimension in its first 3 messages; object 2: never a dimension; object 3: type
    UNKNOWN; message 10's timestamp is later than message 11's."""
    t = 5.0 + 0.1 * np.arange(n)
    t[10], t[11] = t[11], t[10]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        msgs = []
        for i, ti in enumerate(t):
            mos = []
            for oid, y, typ in ((1, -1.75, "VEHICLE"), (2, -5.25, "VEHICLE"), (3, -8.75, "UNKNOWN")):
                dim = ({} if (oid == 1 and i < 3) or oid == 2 else
                       {"dimension": b.Dimension3d(length=4.5, width=1.8, height=1.5)})
                kw = {}
                if typ == "VEHICLE":
                    kw["vehicle_classification"] = b.MovingObjectVehicleClassification(
                        type=b.MovingObjectVehicleClassificationType.MEDIUM_CAR)
                mos.append(b.MovingObject(
                    id=b.Identifier(value=oid), type=getattr(b.MovingObjectType, typ),
                    base=b.BaseMoving(position=b.Vector3d(x=10.0 + 20 * (ti - 5), y=y, z=0.75),
                                      orientation=b.Orientation3d(yaw=0.0),
                                      velocity=b.Vector3d(x=20.0, y=0.0, z=0.0), **dim), **kw))
            sec = int(ti)
            msgs.append(b.GroundTruth(timestamp=b.Timestamp(seconds=sec, nanos=int(round(
                (ti - sec) * 1e9))), moving_object=mos))
    with open(path, "wb") as f:
        for m in msgs:
            data = m.to_binary()
            f.write(struct.pack("<I", len(data)) + data)
    return path


def test_osi_submission_findings_name_message_and_object(capsys, tmp_path):
    p = osi_trace(tmp_path / "trace.osi")
    code, out, err = cli(capsys, "validate", p, "--map", STRAIGHT_MAP, "--format", "json",
                         "--select", "source")
    rep = Report.from_json(out)
    assert code == 1, err  # an object without any dimension is an error
    res = source_results(rep)
    dims = {(f.location.object_id, f.location.message_index, f.count)
            for f in res["source.osi.missing_dimension"].sample}
    assert dims == {(1, 0, 3), (2, 0, 20)}
    assert res["source.osi.missing_dimension"].count == 23
    unk = res["source.osi.unknown_type"].sample
    assert [(f.location.object_id, f.location.message_index) for f in unk] == [(3, 0)]
    tm = res["source.osi.time_not_increasing"].sample
    assert [(f.location.message_index, f.location.object_id) for f in tm] == [(11, None)]
    assert all(f.location.file == str(p) for r in res.values() for f in r.sample)
    # the import itself: object 2 is not a participant, object 1 has the size of message 3
    with collect_source_findings():
        rec = convert("osi", [p], map_source=STRAIGHT_MAP)
    parts = {r["source_id"]: r for r in rec.participants.to_pylist()}
    assert set(parts) == {"1", "3"} and parts["1"]["length"] == 4.5
    assert parts["3"]["class"] == "other"
    assert rec.states.num_rows == 40


def test_osi_convert_still_warns_located(tmp_path):
    p = osi_trace(tmp_path / "trace.osi")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        convert("osi", [p], map_source=STRAIGHT_MAP)
    said = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    assert f"{p}: message index 0, object id 2: moving object 2 has no positive base.dimension " \
           "(length, width) in any of its messages: not imported (20 times)" in said
    assert f"{p}: message index 11: timestamp 6 s is earlier than the previous message's " \
           "(6.1 s); the states are sorted" in said


# --- OpenSCENARIO end to end -----------------------------------------------------------------------

XOSC = """<?xml version="1.0"?>
<OpenSCENARIO><FileHeader revMajor="1" revMinor="2" date="2026-01-01T00:00:00" description="t" author="me"/>
<ParameterDeclarations/><CatalogLocations/><RoadNetwork><LogicFile filepath="map.xodr"/></RoadNetwork>
<Entities>
<ScenarioObject name="A"><Vehicle name="car" vehicleCategory="car"><BoundingBox><Center x="0" y="0" z="0.7"/>
<Dimensions width="1.8" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
<ScenarioObject name="NoBox"><Vehicle name="car" vehicleCategory="car"></Vehicle></ScenarioObject>
<ScenarioObject name="Odd"><Vehicle name="x" vehicleCategory="hovercraft"><BoundingBox><Center x="0" y="0" z="0.7"/>
<Dimensions width="1.8" length="4.5" height="1.4"/></BoundingBox></Vehicle></ScenarioObject>
</Entities>
<Storyboard><Init><Actions>
<Private entityRef="A"><PrivateAction><TeleportAction><Position><WorldPosition x="10" y="-1.75" h="0"/></Position></TeleportAction></PrivateAction>
<PrivateAction><LongitudinalAction><SpeedAction><SpeedActionDynamics dynamicsShape="step" dynamicsDimension="time" value="0"/>
<SpeedActionTarget><AbsoluteTargetSpeed value="10"/></SpeedActionTarget></SpeedAction></LongitudinalAction></PrivateAction>
<PrivateAction><RoutingAction><FollowTrajectoryAction><TrajectoryRef>
<Trajectory name="tr" closed="false"><Shape><Polyline>
<Vertex time="0"><Position><WorldPosition x="10" y="-1.75"/></Position></Vertex>
<Vertex><Position><WorldPosition x="40" y="-1.75"/></Position></Vertex>
</Polyline></Shape></Trajectory></TrajectoryRef>
<TimeReference><Timing domainAbsoluteRelative="absolute" scale="1" offset="0"/></TimeReference>
<TrajectoryFollowingMode followingMode="position"/></FollowTrajectoryAction></RoutingAction></PrivateAction></Private>
<Private entityRef="Odd"><PrivateAction><TeleportAction><Position><WorldPosition x="60" y="-5.25" h="0"/></Position></TeleportAction></PrivateAction></Private>
</Actions></Init><StopTrigger><ConditionGroup><Condition name="c" delay="0" conditionEdge="rising"><ByValueCondition>
<SimulationTimeCondition value="4" rule="greaterThan"/></ByValueCondition></Condition></ConditionGroup></StopTrigger></Storyboard>
</OpenSCENARIO>"""


def test_openscenario_submission_findings_name_entity_and_line(capsys, tmp_path):
    (tmp_path / "map.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    p = tmp_path / "s.xosc"
    p.write_text(XOSC)
    lines = XOSC.splitlines()

    def line_of(needle: str) -> int:
        return next(i for i, t in enumerate(lines, 1) if needle in t)

    code, out, err = cli(capsys, "validate", p, "--format", "json")
    rep = Report.from_json(out)
    assert code == 1, err  # an entity without a bounding box is not converted: an error
    res = source_results(rep)
    (nb,) = res["source.openscenario.no_bounding_box"].sample
    assert (nb.location.entity, nb.location.line) == ("NoBox", line_of('name="NoBox"'))
    (cat,) = res["source.openscenario.unknown_category"].sample
    assert (cat.location.entity, cat.location.line) == ("Odd", line_of("hovercraft"))
    (vt,) = res["source.openscenario.vertex_without_time"].sample
    assert (vt.location.entity, vt.location.line) == ("A", line_of('<Vertex><Position><WorldPosition x="40"'))
    assert all(f.location.file == str(p) for r in res.values() for f in r.sample)
    # the text report: one greppable line per finding, located in the file's terms
    code, out, _ = cli(capsys, "validate", p, "--select", "source")
    nobox = line_of('name="NoBox"')
    assert f"{p}:{nobox} entity=NoBox: entity 'NoBox' not converted" in out


def test_an_unimportable_submission_exits_3_located(capsys, tmp_path):
    (tmp_path / "map.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    p = tmp_path / "broken.xosc"
    p.write_text(XOSC.replace("</Entities>", "</Entitie>"))
    code, out, err = cli(capsys, "validate", p)
    assert code == 3 and out == ""
    assert err.startswith(f"aveas-format: error: {p}: line ") and "malformed XML" in err
    q = tmp_path / "data.bin"
    q.write_bytes(b"\0" * 10)
    code, out, err = cli(capsys, "validate", q)
    assert code == 3 and "no converter reads files like it" in err


def test_ambiguous_extension_needs_from_unless_the_content_tells(capsys, tmp_path):
    """.json is OpenLABEL or an infrastructure-lidar track list: an OpenLABEL document says so in
    its first bytes; another JSON needs --from."""
    from aveas_format.converters.registry import importers_for

    assert importers_for(openlabel_submission(tmp_path)) == ["openlabel"]
    other = tmp_path / "tracks.json"
    other.write_text(json.dumps({"tracks": []}))
    code, _, err = cli(capsys, "validate", other)
    assert code == 2 and "several converters read .json" in err and "--from" in err


def test_openscenario_bounding_box_that_is_no_number_is_located(capsys, tmp_path):
    """(Found by make fuzz: a flipped byte in a Dimensions value was a ValueError traceback.)"""
    (tmp_path / "map.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
    p = tmp_path / "s.xosc"
    bad = XOSC.replace('<ScenarioObject name="Odd"><Vehicle name="x" vehicleCategory="hovercraft"><BoundingBox>'
                       '<Center x="0" y="0" z="0.7"/>\n<Dimensions width="1.8" length="4.5"',
                       '<ScenarioObject name="Odd"><Vehicle name="x" vehicleCategory="hovercraft"><BoundingBox>'
                       '<Center x="0" y="0" z="0.7"/>\n<Dimensions width="1.8" length=":.5"')
    assert bad != XOSC
    p.write_text(bad)
    code, out, err = cli(capsys, "validate", p, "--format", "json")
    assert code == 1, err
    found = {(f.location.entity, f.location.line) for f in
             source_results(Report.from_json(out))["source.openscenario.no_bounding_box"].sample}
    lines = bad.splitlines()
    assert ("Odd", next(i for i, t in enumerate(lines, 1) if 'length=":.5"' in t)) in found


# --- the Python API takes a submitted file as the CLI does ----------------------------------------

def _comparable(report_json: str) -> dict:
    """A JSON report without what differs from run to run (timings)."""
    def strip(v):
        if isinstance(v, dict):
            return {k: strip(x) for k, x in v.items() if k not in ("seconds", "created")}
        if isinstance(v, list):
            return [strip(x) for x in v]
        return v
    return strip(json.loads(report_json))


@pytest.mark.parametrize("kind", ["osi", "openscenario"])
def test_the_api_validates_a_foreign_file_as_the_cli_does(capsys, tmp_path, kind):
    """``aveas_format.validate(FILE)`` imports the file as ``aveas-format validate FILE`` does
    (the importer sniffed from the file, the import's located findings as source.* rules): the
    same JSON report."""
    from aveas_format.validate.render import render_json

    if kind == "osi":
        p = osi_trace(tmp_path / "trace.osi")
        args, kw = ["--map", STRAIGHT_MAP], {"map_source": STRAIGHT_MAP}
    else:
        (tmp_path / "map.xodr").write_bytes(STRAIGHT_MAP.read_bytes())
        p = tmp_path / "s.xosc"
        p.write_text(XOSC)
        args, kw = [], {}
    code, out, err = cli(capsys, "validate", p, *args, "--format", "json")
    api = aveas_format.validate(p, **kw)
    assert code == api.exit_code("error") == 1, err
    assert _comparable(render_json(api)) == _comparable(out)
    assert api.recording == str(p) and any(r.code.startswith("source.") for r in api.results)


def test_the_api_takes_the_converter_and_its_options(tmp_path):
    """``converter=``/``options=`` as ``--from``/``-O``; a file no importer reads is the located
    error the CLI exits 3 with."""
    p = osi_trace(tmp_path / "trace.osi")
    rep = aveas_format.validate([p], converter="osi", map_source=STRAIGHT_MAP,
                                options={"host_role": "recording_vehicle"}, select=["source.osi"])
    assert {r.code for r in rep.results} == {"source.osi.missing_dimension",
                                             "source.osi.unknown_type",
                                             "source.osi.time_not_increasing"}
    q = tmp_path / "data.bin"
    q.write_bytes(b"\0" * 10)
    with pytest.raises(aveas_format.RecordingIOError, match="no converter reads files like it"):
        aveas_format.validate(q)


# --- sniffing: each importer declares how to recognise its files ----------------------------------

@pytest.mark.parametrize("name,header,expected", [
    ("log.csv", "time,id,x,y,heading,vx,vy\n0,ego,1,2,0,1,0\n", ["driving-simulator"]),
    ("boxes.csv", "frame,track_id,cx,cy,w,h,angle,class\n0,1,1,1,3,1,0,car\n", ["rotated-boxes"]),
    ("fcd.csv", "timestep_time;vehicle_id;vehicle_x;vehicle_y;vehicle_angle\n", ["sumo-fcd"]),
    ("gt.txt", "1,1,100,200,30,60,1,-1,-1,-1\n", ["infra-lwir"]),
    ("marks.csv", "u,v,x,y\n1,2,3,4\n", ["infra-lwir"]),
    ("tracks.csv", "time,track_id,class,x,y,z,yaw,length,width,height\n", ["infra-lidar"]),
    ("01_tracks.csv", "frame,id,x,y,width,height,xVelocity,yVelocity\n", ["highd"]),
    ("07_tracks.csv", "recordingId,trackId,frame,xCenter,yCenter,heading\n", ["ind"]),
    ("07_tracks.csv", "recordingId,trackId,frame,xCenter,yCenter,heading,laneletId\n", ["exid"]),
    ("dynamics.csv", "participant_id,step,x,y,vx,vy\n", ["accident"]),
    ("run.xml", '<?xml version="1.0"?>\n<fcd-export>\n<timestep time="0"/>\n', ["sumo-fcd"]),
    ("other.csv", "a,b\n1,2\n", ["driving-simulator", "infra-lidar", "infra-lwir", "rotated-boxes",
                                  "sumo-fcd"]),
])
def test_each_importer_recognises_its_files(tmp_path, name, header, expected):
    """Where several importers' patterns match a file, their ``sniff`` of its first bytes tells
    them apart; where none recognises it, every match is named (validate asks for --from)."""
    from aveas_format.converters.registry import importers_for

    p = tmp_path / name
    p.write_text(header)
    assert [n for n in importers_for(p) if n != "partner-csv"] == expected
