"""`aveas-format validate|derive|catalog DATASET`: many recordings, one task each."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq


def cli(*args):
    return subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_validate_a_dataset_streams_reports_and_exits_with_the_worst(broken_dataset, tmp_path):
    res = cli("validate", broken_dataset, "--workers", "2", "--reports-dir", tmp_path / "r")
    assert res.returncode == 3, res.stderr
    lines = res.stdout.splitlines()
    assert any(ln.endswith("v2.aveas: findings (1 errors, 0 warnings, 0 infos)") for ln in lines)
    assert any("corrupt.aveas.zip: FAILED RecordingIOError" in ln for ln in lines)
    assert lines[-1].startswith("6 recordings: 4 valid, 1 with findings, 1 failed")
    assert "failed" in res.stderr and "corrupt.aveas.zip" in res.stderr  # streamed
    d = json.loads((tmp_path / "r" / "dataset-report.json").read_text())
    assert d["exit_code"] == 3 and d["by_rule"]["structure.row_count"]["count"] == 1
    assert "<h2>Worst recordings</h2>" in (tmp_path / "r" / "dataset-report.html").read_text()
    assert len(list((tmp_path / "r").glob("*.json"))) == 6  # 5 reports + the dataset's
    assert len(list((tmp_path / "r").glob("*.html"))) == 6  # the same as HTML pages
    # JSON and HTML on stdout / to a file; several paths and globs; --fail-on
    res = cli("validate", broken_dataset / "kit", str(broken_dataset / "tub" / "v*.aveas"),
              "-j", "1", "--format", "json")
    assert res.returncode == 1
    d = json.loads(res.stdout)
    assert d["recordings"] == 5 and d["worst"][0]["path"].endswith("v2.aveas")
    assert cli("validate", broken_dataset / "kit", broken_dataset / "tub" / "v2.aveas",
               "--fail-on", "never").returncode == 0
    res = cli("validate", broken_dataset / "kit", "--format", "html", "-o", tmp_path / "d.html")
    assert res.returncode == 0 and "3 recordings: 3 valid" in res.stderr
    assert "Dataset validate report" in (tmp_path / "d.html").read_text()
    # usage errors stay usage errors
    res = cli("validate", broken_dataset, "--select", "nonsense")
    assert res.returncode == 2 and "unknown rule or family" in res.stderr


def test_derive_a_dataset(dataset_root, tmp_path):
    out = tmp_path / "derived"
    res = cli("derive", dataset_root / "tub", tmp_path / "missing.aveas", "-o", out, "-j", "2",
              "--only", "kinematics", "--report", tmp_path / "derive.html")
    assert res.returncode == 3, res.stderr
    d = json.loads(res.stdout)
    assert d["completed"] == 2 and d["failed"] == 1
    assert "no such recording" in d["failures"][0]["error"]
    assert sorted(p.name for p in out.iterdir()) == ["v1.aveas", "v2.aveas"]
    assert all("kinematics" in r["derived"] for r in d["results"])
    assert "derived 2 of 3 recordings, 1 failed" in res.stderr
    assert "<h2>Recordings</h2>" in (tmp_path / "derive.html").read_text()
    res = cli("derive", dataset_root / "tub", "-o", out / "v1.aveas")  # a recording, not a dir
    assert res.returncode == 2


def test_catalog_command(broken_dataset, tmp_path):
    res = cli("catalog", broken_dataset, "-o", tmp_path / "catalog.parquet", "-j", "2")
    assert res.returncode == 3 and "1 could not be read" in res.stderr
    t = pq.read_table(tmp_path / "catalog.parquet")
    assert t.num_rows == 6
    rows = {Path(r["path"]).name: r for r in t.to_pylist()}
    assert rows["v2.aveas"]["errors"] == 1 and rows["v2.aveas"]["valid"] is False
    assert rows["a1.aveas"]["valid"] is True and rows["a1.aveas"]["min_ttc_s"] > 0
    assert rows["corrupt.aveas.zip"]["read_error"].startswith("RecordingIOError")
    res = cli("catalog", broken_dataset / "kit", "-o", tmp_path / "catalog.parquet")
    assert res.returncode == 2 and "exists" in res.stderr
    res = cli("catalog", broken_dataset / "kit", "-o", tmp_path / "catalog.parquet",
              "--overwrite", "--no-validate", "-j", "1")
    assert res.returncode == 0
    assert pq.read_table(tmp_path / "catalog.parquet").column("validated").to_pylist() == [False] * 3
