"""Valid recordings stay valid; configuration; report formats (JSON Schema, HTML); figures; CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest

import aveas_format
import helpers_validate as vf
from aveas_format.errors import FormatError
from aveas_format.validate.config import ValidationConfig, config_toml
from aveas_format.plot.report_html import render_html
from aveas_format.validate.report import report_json_schema

EXAMPLE = Path(__file__).resolve().parent.parent / "data" / "versions" / "1.0.0" / "example.aveas"


def cli(*args):
    return subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def highway():
    from aveas_format.sample import highway_scene

    return highway_scene()


def test_demo_recording_has_no_error(highway):
    report = aveas_format.validate(highway)
    assert report.failures == []
    assert report.counts["error"] == 0, report.flatten(("code", "message"))


def test_frozen_example_has_no_error():
    report = aveas_format.validate(EXAMPLE)
    assert report.failures == [] and report.counts["error"] == 0, report.flatten(("code", "message"))


def test_conformance_recording_has_no_error(conformance_path):
    report = aveas_format.validate(conformance_path)
    assert report.failures == [] and report.counts["error"] == 0, report.flatten(("code", "message"))


# --- configuration -------------------------------------------------------------------------------


def test_config_defaults_overrides_and_toml(tmp_path):
    cfg = ValidationConfig.load({"classes": {"car": {"speed_max": 20.0}}, "geo": {
        "lonlat_tolerance_m": 0.5}})
    assert cfg.classes["car"].speed_max == 20.0
    assert cfg.classes["car"].length == (2.5, 7.0)  # merged key by key with the defaults
    assert cfg.classes["truck"].speed_max == 45.0 and cfg.geo.lonlat_tolerance_m == 0.5
    f = tmp_path / "v.toml"
    f.write_text(config_toml(cfg))
    assert ValidationConfig.load(f) == cfg  # the TOML template round-trips
    f.write_text("[kinematics]\nwindwo_s = 1.0\n")
    with pytest.raises(FormatError, match="windwo_s"):
        ValidationConfig.load(f)
    with pytest.raises(FormatError, match="unknown classes"):
        ValidationConfig.load({"classes": {"spaceship": {"speed_max": 1.0}}})


def test_thresholds_change_the_findings(clean):
    """The clean cars drive 25-33 m/s: a car limit of 20 m/s flags them, as the config says."""
    report = aveas_format.validate(clean, select=["kinematics.speed"],
                                   config={"classes": {"car": {"speed_max": 20.0}}})
    assert report.flatten(("code", "participant_id")) == [["kinematics.speed", 0],
                                                          ["kinematics.speed", 3]]
    assert report.findings()[0].context["limit"] == 20.0


def test_findings_carry_typed_locations(scene):
    scene["tracks"][0]["x"][75:] += 3.0
    report = aveas_format.validate(vf.build(scene), select=["kinematics.position_jump"])
    (f,) = report.findings()
    loc = f.location
    assert (loc.table, loc.row, loc.participant_id, loc.column) == ("states", 75, 0, "x,y")
    assert loc.time == pytest.approx(3.0) and loc.x == pytest.approx(100 + 75.0 + 3.0)
    assert f.message.startswith("states.parquet: row 75: participant 0 moves")


# --- reports -------------------------------------------------------------------------------------


def test_json_report_validates_against_its_schema(scene):
    scene["participants"]["length"][0] = 9.0
    report = aveas_format.validate(vf.build(scene))
    jsonschema.Draft202012Validator(report_json_schema()).validate(json.loads(report.to_json()))


def test_html_report_is_self_contained(scene):
    scene["tracks"][0]["x"][75:] += 3.0
    rec = vf.build(scene)
    report = aveas_format.validate(rec)
    page = render_html(report, rec)
    assert page.startswith("<!DOCTYPE html>") and "</html>" in page
    assert "kinematics.position_jump" in page and "INVALID" in page
    assert page.count("data:image/png;base64,") == 4
    assert "http://" not in page and "https://" not in page and "<script" not in page


def test_html_report_without_recording_says_so(clean):
    page = render_html(aveas_format.validate(clean), None)
    assert "No figures" in page and "No findings" in page


def test_plot_writes_pngs(tmp_path, clean):
    from aveas_format.plot import save_figures

    paths = save_figures(clean, tmp_path / "fig")
    assert sorted(p.name for p in paths) == ["acceleration.png", "map.png", "sample_rate.png",
                                             "speed.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)


# --- CLI -----------------------------------------------------------------------------------------


def test_cli_config_html_and_schema(tmp_path, scene):
    scene["participants"]["length"][0] = 9.0  # a warning only
    path = vf.build(scene).write(tmp_path / "w.aveas")
    assert cli("validate", path).returncode == 0
    assert cli("validate", path, "--fail-on", "warning").returncode == 1
    cfg = tmp_path / "c.toml"
    cfg.write_text("[classes.car]\nlength = [2.5, 10.0]\n")
    assert cli("validate", path, "--fail-on", "warning", "--config", cfg).returncode == 0
    cfg.write_text("[classes.car]\nlenght = [2.5, 10.0]\n")
    res = cli("validate", path, "--config", cfg)
    assert res.returncode == 2 and "lenght" in res.stderr
    out = tmp_path / "r.html"
    assert cli("validate", path, "--format", "html", "-o", out).returncode == 0
    assert "participants.size_implausible" in out.read_text()
    res = cli("validate", "--report-schema")
    assert res.returncode == 0 and json.loads(res.stdout) == report_json_schema()
    res = cli("validate", "--print-config")
    assert res.returncode == 0 and "[classes.car]" in res.stdout
    res = cli("plot", path, "-o", tmp_path / "figs")
    assert res.returncode == 0 and (tmp_path / "figs" / "map.png").exists()


def test_figures_of_a_large_recording_read_a_participant_subset(tmp_path):
    """Above the figure row budget, figures draw every k-th participant (and say so); findings
    located by state row only get their x/y from the file."""
    import test_rule_corpus as corpus
    import helpers_validate as vf

    from aveas_format.plot.recording import open_for_figures
    from aveas_format.plot.report_html import render_html

    path = corpus.c_out_of_range(vf.fresh()).write(tmp_path / "r.aveas")
    report = aveas_format.validate(path)
    f = report.results[0].sample[0]
    assert f.location.row is not None and f.location.x is None
    total = aveas_format.open(path).states.num_rows
    rec = open_for_figures(path, report, max_rows=total // 3)
    assert 0 < rec.states.num_rows < total
    assert set(rec.states.column_names) >= {"participant_id", "time", "x", "y"}
    assert "participant" in rec.figure_note
    full = aveas_format.open(path).states
    assert f.location.x == full.column("x")[f.location.row].as_py()
    assert "drawn from every" in render_html(report, rec)
    small = open_for_figures(path, report)
    assert small.states.num_rows == total and getattr(small, "figure_note", None) is None
