"""The CLI: commands, exit codes, one-line errors, JSON output equal to the API."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

import aveas_format
from aveas_format.schema import recording_json_schema, tables_spec


def cli(*args, check_rc=None):
    res = subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                         capture_output=True, text=True, timeout=300)
    if check_rc is not None:
        assert res.returncode == check_rc, (res.returncode, res.stdout[-2000:], res.stderr[-2000:])
    return res


def test_version():
    res = cli("--version", check_rc=0)
    assert res.stdout.strip() == f"aveas-format {aveas_format.__version__}"


def test_info_text_and_json(conformance_path):
    res = cli("info", conformance_path, check_rc=0)
    assert "conformance-highway-1" in res.stdout and "car 24, truck 6" in res.stdout
    res = cli("info", conformance_path, "--json", check_rc=0)
    data = json.loads(res.stdout)
    assert data["participants_per_class"] == {"car": 24, "truck": 6}
    assert data["duration_s"] == 19.96 and data["observed_rate_hz"] == 25.0
    assert data["tables"] == {"participants": 30, "states": 15000, "unobserved": 1}
    assert data["column_coverage"]["x"] == 1.0


def test_schema_outputs():
    assert json.loads(cli("schema", check_rc=0).stdout) == recording_json_schema()
    assert json.loads(cli("schema", "--tables", check_rc=0).stdout) == tables_spec()


@pytest.mark.parametrize("args,rc,needle", [
    (("info", "does-not-exist.aveas"), 3, "does-not-exist.aveas: no such recording"),
    (("validate", "does-not-exist.aveas"), 3, "no such recording"),
    (("info",), 2, "Missing argument"),
    (("frobnicate",), 2, "No such command"),
    (("validate", "{rec}", "--select", "nonsense"), 2, "unknown rule or family 'nonsense'"),
    (("validate", "{rec}", "--fail-on", "sometimes"), 2, "Invalid value"),
])
def test_errors_are_one_clear_line(written, args, rc, needle):
    res = cli(*[a.replace("{rec}", str(written)) for a in args])
    assert res.returncode == rc
    assert needle in res.stderr
    assert "Traceback" not in res.stderr
    if rc == 3:
        assert len(res.stderr.strip().splitlines()) == 1


def test_debug_shows_the_traceback():
    res = cli("--debug", "info", "does-not-exist.aveas")
    assert res.returncode == 3 and "Traceback" in res.stderr


def test_damaged_recording_gives_exit_3(written):
    (written / "recording.json").write_text("{ not json")
    res = cli("info", written)
    assert res.returncode == 3
    assert "recording.json: line 1, column 3: broken JSON" in res.stderr


def test_validate_exit_codes_and_json_equals_api(written):
    res = cli("validate", written, "--format", "json", check_rc=0)
    api = aveas_format.validate(written)
    cli_report, api_report = json.loads(res.stdout), json.loads(api.to_json())
    for r in (cli_report, api_report):  # timings differ between two runs; nothing else may
        r.pop("seconds")
        for rr in r["results"]:
            rr.pop("seconds")
    assert cli_report == api_report
    api_d = json.loads(api.to_json())
    api_d.pop("seconds")
    for rr in api_d["results"]:
        rr.pop("seconds")
    assert cli_report == api_d
    # break it: a duplicated state row
    meta = json.loads((written / "recording.json").read_text())
    meta["tables"]["states"]["rows"] = 1
    (written / "recording.json").write_text(json.dumps(meta))
    res = cli("validate", written)
    assert res.returncode == 1
    assert "ERROR   structure.row_count" in res.stdout and "INVALID" in res.stdout
    assert cli("validate", written, "--fail-on", "never").returncode == 0
    assert cli("validate", written, "--ignore", "structure.row_count").returncode == 0
    out = written.parent / "report.json"
    cli("validate", written, "--format", "json", "--output", out)
    assert json.loads(out.read_text())["results"][0]["code"] == "structure.row_count"


def test_demo(tmp_path):
    """The demo writes the vehicles asked for (40 in 5 s: more than a 1 km road sees, so the road
    is lengthened, and it says so), ends with its HTML report and figures, prints the next
    commands, and refuses to replace its output without --overwrite."""
    demo = tmp_path / "demo"
    res = cli("demo", "--output", demo, "--vehicles", "40", "--duration", "5", check_rc=0)
    assert "VALID" in res.stdout and "equal to the directory form: True" in res.stderr
    rec = aveas_format.open(demo / "highway.aveas.zip")
    assert rec.participants.num_rows == 40
    assert "so that all 40 vehicles drive on it" in res.stderr
    assert rec.unobserved.num_rows == 2
    s = rec.states
    assert {"x_std", "y_std", "heading_std", "vx_std", "vy_std", "interpolated"} <= set(s.column_names)
    assert s.column("road_id").null_count == 0
    html = (demo / "report.html").read_text()
    assert html.startswith("<!DOCTYPE html") or "<html" in html[:500]
    assert "data:image/png;base64," in html
    figures = sorted(p.name for p in (demo / "figures").glob("*.png"))
    assert "map.png" in figures and len(figures) >= 4
    assert all((demo / "figures" / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for f in figures)
    nxt = res.stdout[res.stdout.index(f"Look at {demo / 'report.html'}"):].splitlines()
    commands = [line.split("#")[0].strip() for line in nxt[1:] if line.startswith("  aveas-format ")]
    assert len(commands) == 3 and commands[0].startswith(f"aveas-format info {demo / 'conflicts.aveas'}")
    assert commands[1].startswith(f"aveas-format derive {demo / 'highway.aveas'}")
    for command in commands:  # they run as printed
        cli(*command.split()[1:], check_rc=0)
    again = cli("demo", "--output", demo, "--vehicles", "3", "--duration", "2")
    assert again.returncode == 2 and "pass --overwrite" in again.stderr
    assert aveas_format.open(demo / "highway.aveas").participants.num_rows == 40


def test_info_gives_the_coverage_in_lonlat(written):
    """The coverage polygon (local frame) also as lon/lat bounds through the recording's CRS."""
    import pyproj

    res = cli("info", written, "--format", "json", check_rc=0)
    b = json.loads(res.stdout)["coverage_lonlat_bounds"]
    crs = aveas_format.open(written).meta.crs
    to_wgs84 = pyproj.Transformer.from_crs(pyproj.CRS(crs), "EPSG:4326", always_xy=True)
    lon0, lat0 = to_wgs84.transform(0.0, -12.0)       # the coverage's corners (small_recording)
    lon1, lat1 = to_wgs84.transform(1000.0, 2.0)
    assert b == pytest.approx([lon0, lat0, lon1, lat1], abs=1e-6)
    text = cli("info", written, check_rc=0).stdout
    assert f"lon {b[0]:.6f} .. {b[2]:.6f}, lat {b[1]:.6f} .. {b[3]:.6f}" in text


_FAR_XOSC = """<?xml version="1.0"?><OpenSCENARIO><FileHeader revMajor="1" revMinor="2" date="x"
description="far" author="me"/><ParameterDeclarations/><CatalogLocations/><RoadNetwork/>
<Entities><ScenarioObject name="A"><Vehicle name="car" vehicleCategory="car"><BoundingBox>
<Center x="0" y="0" z="0.7"/><Dimensions width="1.8" length="4.5" height="1.4"/></BoundingBox>
</Vehicle></ScenarioObject></Entities><Storyboard><Init><Actions><Private entityRef="A">
<PrivateAction><RoutingAction><FollowTrajectoryAction><Trajectory name="t" closed="false"><Shape>
<Polyline>{vertices}</Polyline></Shape></Trajectory><TimeReference><Timing
domainAbsoluteRelative="absolute" scale="1" offset="0"/></TimeReference><TrajectoryFollowingMode
followingMode="position"/></FollowTrajectoryAction></RoutingAction></PrivateAction></Private>
</Actions></Init><StopTrigger/></Storyboard></OpenSCENARIO>"""


def test_convert_onto_the_wrong_map_says_so(tmp_path):
    """Issue 18, point 7: positions on no road of the map are an error at the end of a conversion
    (exit 1 with --validate; a warning line with --no-validate), and the summary gives the share
    of states on the map. Here x and y are swapped: the message says that this fits."""
    from helpers_common import STRAIGHT_MAP

    vertices = "".join(f'<Vertex time="{t / 10}"><Position><WorldPosition x="-5.25" y="{20 + t}" '
                       f'h="1.5708"/></Position></Vertex>' for t in range(60))
    src = tmp_path / "far.xosc"
    src.write_text(_FAR_XOSC.format(vertices=vertices))
    args = ["convert", "--from", "openscenario", str(src), "--map", str(STRAIGHT_MAP), "-o",
            str(tmp_path / "far.aveas"), "-O", "license=CC0-1.0"]
    r = cli(*args)
    assert r.returncode == 1, r.stderr
    assert "0.0% on the map" in r.stderr
    assert "map.mostly_off_road" in r.stdout and "with x and y swapped, 100%" in r.stdout
    r = cli(*args, "--overwrite", "--no-validate")
    assert r.returncode == 0, r.stderr
    assert ("warning: converter openscenario: the recording is mostly off its map: 60 of 60 "
            "vehicle states (100.0 %) are on no road" in r.stderr)
    assert "with x and y swapped, 100%" in r.stderr and "--crs" in r.stderr
    assert r.stderr.count("mostly off its map") == 1
