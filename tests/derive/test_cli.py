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
