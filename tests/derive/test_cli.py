"""``aveas-format derive``."""

from __future__ import annotations

import json

from typer.testing import CliRunner

import aveas_format
from aveas_format.cli.app import app
from aveas_format.sample import highway_scene

runner = CliRunner()


def test_derive_cli(tmp_path):
    src = highway_scene(n_vehicles=10, duration_s=4.0).write(tmp_path / "a.aveas")
    out = tmp_path / "b.aveas.zip"
    r = runner.invoke(app, ["derive", str(src), "--only", "kinematics", "-o", str(out)])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout[r.stdout.index("{"):r.stdout.rindex("}") + 1])
    assert summary["derived"] == ["kinematics"]
    assert list(aveas_format.open(out).derived) == ["kinematics"]
    # never overwrite without being told
    r = runner.invoke(app, ["derive", str(src), "-o", str(out)])
    assert r.exit_code == 2 and "exists" in r.output
    r = runner.invoke(app, ["derive", str(src)])
    assert r.exit_code == 2
    r = runner.invoke(app, ["derive", str(src), "--only", "bogus", "-o", str(tmp_path / "c")])
    assert r.exit_code == 2 and "unknown derivation" in r.output
    r = runner.invoke(app, ["derive", str(src), "--in-place", "--ttc", "2.5",
                            "--param", "traffic.cell_duration_s=2"])
    assert r.exit_code == 0, r.output
    back = aveas_format.open(src)
    assert set(back.derived) == {"kinematics", "interactions", "encroachments", "traffic",
                                 "conflicts", "criticality_summary"}
    assert {t["time_end"] - t["time_start"] for t in back.derived["traffic"].to_pylist()} == {2.0}
    r = runner.invoke(app, ["derive", str(src), "--in-place", "--param", "kinematics.nope=1"])
    assert r.exit_code == 3 and "nope" in r.output


def test_derive_by_windows_cli(tmp_path):
    """``--window``: the criticality tables by time windows (the same tables as at once:
    tests/derive/test_streamed.py), in place or to --output, one recording; what is not derived
    by windows is a usage error."""
    src = highway_scene(n_vehicles=10, duration_s=6.0).write(tmp_path / "a.aveas")
    out = tmp_path / "w.aveas"
    r = runner.invoke(app, ["derive", str(src), "--window", "2", "-j", "1", "-o", str(out),
                            "--param", "interactions.velocities=states", "--ttc", "2"])
    assert r.exit_code == 0, r.output
    summary = json.loads(r.stdout[r.stdout.index("{"):r.stdout.rindex("}") + 1])
    assert summary["windows"] == 3 and summary["derived"] == [
        "kinematics", "interactions", "conflicts", "events", "criticality_summary"]
    assert summary["events"] == aveas_format.open(out).events.num_rows
    back = aveas_format.open(out)
    assert summary["tables"]["derived/interactions"] == back.derived["interactions"].num_rows > 0
    e = {x.table: x for x in back.meta.derived}
    assert e["derived/interactions"].parameters["velocities"] == "states"
    assert e["derived/criticality_summary"].parameters["ttc_s"] == 2
    for args, needle in ((["--only", "traffic"], "not derived by windows"),
                         (["--pet", "1"], "PET events need encroachments"),
                         (["--param", "traffic.cell_duration_s=2"], "not derived by windows")):
        r = runner.invoke(app, ["derive", str(src), "--window", "2", "-o",
                                str(tmp_path / "x.aveas"), *args])
        assert r.exit_code == 2 and needle in r.output, (args, r.output)
    r = runner.invoke(app, ["derive", str(src), "--window", "2", "-j", "1", "--in-place"])
    assert r.exit_code == 0, r.output
    assert set(aveas_format.open(src).derived) == {"kinematics", "interactions", "conflicts",
                                                   "criticality_summary"}
