"""``aveas-format map``: info, project, plot, check (run as subprocesses)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq
import pytest

from aveas_format.cli.map import map_summary
from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import curved_highway


def cli(*args, check_rc=None):
    res = subprocess.run([sys.executable, "-m", "aveas_format", "map", *map(str, args)],
                         capture_output=True, text=True, timeout=300)
    if check_rc is not None:
        assert res.returncode == check_rc, (res.returncode, res.stdout[-2000:], res.stderr[-2000:])
    return res


def one_line_error(res, rc: int, needle: str) -> None:
    assert res.returncode == rc, (res.returncode, res.stderr)
    assert needle in res.stderr, res.stderr
    assert "Traceback" not in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr


@pytest.fixture(scope="module")
def hw(tmp_path_factory):
    """A curved highway with a lenient geoReference (no +proj), 2 lanes each way."""
    p = tmp_path_factory.mktemp("map") / "hw.xodr"
    p.write_text(curved_highway(length=400.0, radius=200.0, straight=50.0, spiral=30.0, lanes_left=2,
                                lanes_right=2, geo_reference="+lat_0=49 +lon_0=8"))
    return p


def test_info_text_and_json(hw):
    res = cli("info", hw, check_rc=0)
    assert "roads" in res.stdout and "line 1, spiral 1, arc 1" in res.stdout
    assert "lenient: no +proj" in res.stdout and "Transverse Mercator" in res.stdout
    data = json.loads(cli("info", hw, "--json", check_rc=0).stdout)
    assert data == json.loads(json.dumps(map_summary(load_map(hw))))
    assert data["roads"] == 1 and data["lanes"] == 4 and data["length_m"] == 400.0
    assert data["geometry_types"] == {"line": 1, "spiral": 1, "arc": 1}
    assert data["crs"]["lenient"] is True and data["crs"]["notes"]
    assert data["lane_length_m"]["driving"] == pytest.approx(1600.0)


def test_project_csv_and_parquet(hw, tmp_path):
    net = load_map(hw)
    s = np.array([10.0, 100.0, 250.0, 390.0])
    t = np.array([-1.75, 5.25, -5.0, 2.0])
    x, y, _, hdg = net.road_to_world("1", s, t)
    x = np.r_[x, 5000.0]
    y = np.r_[y, 5000.0]
    pts = tmp_path / "pts.csv"
    pcsv.write_csv(pa.table({"id": list("abcde"), "x": x, "y": y, "heading": np.r_[hdg, 0.0]}), pts)
    res = cli("project", hw, "--points", pts, check_rc=0)  # CSV on stdout
    assert "projected 5 points onto hw.xodr: 4 on a road" in res.stderr
    conv = pcsv.ConvertOptions(column_types={"road_id": pa.string()}, strings_can_be_null=True)
    out = pcsv.read_csv(pa.py_buffer(res.stdout.encode()), convert_options=conv).to_pydict()
    assert out["id"] == list("abcde")
    assert out["road_id"][:4] == ["1"] * 4 and out["road_id"][4] is None
    assert out["lane_id"] == [-1, 2, -2, 1, None]
    np.testing.assert_allclose(out["s"][:4], s, atol=1e-6)
    np.testing.assert_allclose(out["t"][:4], t, atol=1e-6)
    assert out["n_candidates"] == [1, 1, 1, 1, 0]
    np.testing.assert_allclose(out["rel_heading"][:4], 0.0, atol=1e-9)
    # Parquet in and out
    pq_in = tmp_path / "pts.parquet"
    pq.write_table(pa.table({"x": x, "y": y}), pq_in)
    cli("project", hw, "-p", pq_in, "-o", tmp_path / "out.parquet", check_rc=0)
    back = pq.read_table(tmp_path / "out.parquet")
    assert back.column_names == ["x", "y", "road_id", "lane_id", "s", "t", "lane_offset", "n_candidates"]
    np.testing.assert_allclose(back.column("s").to_numpy(zero_copy_only=False)[:4], s, atol=1e-6)
    assert back.column("lane_id").null_count == 1


@pytest.mark.parametrize(
    "content,rc,needle",
    [
        ("x,y\n1,2\n3,abc\n", 3, "pts.csv: line 3, column y: 'abc' is not a number"),
        ("x,y\n1,2\n\n,4\n", 3, "pts.csv: line 4, column x: empty value"),
        ("x,y\n1,2\n3,4,5\n", 3, "pts.csv: line 3: 3 fields, the header has 2"),
        ("a,y\n1,2\n", 3, "pts.csv: no column 'x' (columns: a, y)"),
        (None, 3, "pts.csv: no such file"),
    ],
)
def test_project_errors_name_file_line_column(hw, tmp_path, content, rc, needle):
    pts = tmp_path / "pts.csv"
    if content is not None:
        pts.write_text(content)
    one_line_error(cli("project", hw, "--points", pts), rc, needle)


def test_usage_and_unreadable_map_errors(hw, tmp_path):
    pts = tmp_path / "p.csv"
    pts.write_text("x,y\n1,2\n")
    one_line_error(cli("project", hw), 2, "Missing option '--points'")
    one_line_error(cli("project", hw, "-p", pts, "-o", tmp_path / "o.txt"), 2, "unknown output format '.txt'")
    one_line_error(cli("plot", hw), 2, "Missing option '--output'")
    one_line_error(cli("info", tmp_path / "none.xodr"), 3, "none.xodr: map file not found")
    broken = tmp_path / "broken.xodr"
    broken.write_text("<OpenDRIVE>\n<header/>\n<road>\n</OpenDRIVE>\n")
    one_line_error(cli("check", broken), 3, "broken.xodr: line 4: not well-formed XML")
    assert cli("info").returncode == 2


def test_plot_writes_a_png(hw, tmp_path):
    res = cli("plot", hw, "-o", tmp_path / "map.png", "--dpi", "50", check_rc=0)
    assert "wrote" in res.stderr
    assert (tmp_path / "map.png").read_bytes()[:4] == b"\x89PNG"


def test_check_exit_codes_text_and_json(hw, tmp_path):
    res = cli("check", hw, check_rc=0)
    assert "VALID: 0 errors" in res.stdout and "georef.no_proj" in res.stdout
    # a negative lane width and a successor road that is not in the map: errors -> exit 1
    text = hw.read_text().replace('<width sOffset="0.0" a="3.5"', '<width sOffset="0.0" a="-1.0"', 1)
    text = text.replace("<planView>", '<link><successor elementType="road" elementId="99" contactPoint="start"/>'
                        "</link><planView>", 1)
    bad = tmp_path / "bad.xodr"
    bad.write_text(text)
    res = cli("check", bad, "--format", "json")
    assert res.returncode == 1
    rep = json.loads(res.stdout)
    assert rep["valid"] is False and rep["counts"]["error"] == 2
    codes = {f["code"] for f in rep["findings"] if f["severity"] == "error"}
    assert codes == {"lane.negative_width", "link.missing_road"}
    assert all(f["line"] for f in rep["findings"] if f["severity"] == "error")
    res = cli("check", bad)
    assert res.returncode == 1 and res.stdout.strip().splitlines()[-1].startswith("INVALID: 2 errors")
