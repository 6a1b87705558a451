"""convert over many inputs: one recording per source, in parallel; a broken source is reported."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
import sys

import pytest

import aveas_format
from aveas_format.dataset import conversion_groups, convert_dataset
from aveas_format.errors import AveasError
from aveas_format.opendrive.builder import straight_highway


@pytest.fixture
def sources(tmp_path, sumo_data):
    """Three copies of a real SUMO FCD excerpt (../shared) and a broken one."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("run1", "run2", "run3"):
        shutil.copy(sumo_data / "fcd_cartesian_excerpt.xml", src / f"{name}.xml")
    (src / "broken.xml").write_text("<fcd-export><timestep time='0'><vehicle id='a'")
    m = tmp_path / "west.xodr"
    m.write_text(straight_highway(length=2000.0, lanes_right=1, x0=1600.0, y0=401.65 - 1.75,
                                  hdg=math.pi, geo_reference="+proj=tmerc +lat_0=48.8 +lon_0=11.1 "
                                  "+k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"))
    return src, m


def test_conversion_groups(tmp_path):
    for f in ("01_tracks.csv", "01_tracksMeta.csv", "02_tracks.csv", "notes.txt"):
        (tmp_path / f).write_text("x")
    g = conversion_groups([tmp_path], group=r"^(\d+)_")
    assert sorted(g) == ["01", "02"] and len(g["01"]) == 2
    assert sorted(conversion_groups([tmp_path / "01_tracks.csv", tmp_path / "02_tracks.csv"])) == \
        ["01_tracks", "02_tracks"]
    with pytest.raises(AveasError, match="exactly one capture group"):
        conversion_groups([tmp_path], group=r"\d+")


def test_convert_many_in_parallel_reports_the_broken_source(sources, tmp_path):
    src, m = sources
    rep = convert_dataset(sorted(src.iterdir()), source="sumo-fcd", output_dir=tmp_path / "out",
                          map_source=str(m), workers=2)
    d = rep.to_dict()
    assert d["completed"] == 3 and d["failed"] == 1
    assert "broken" in d["failures"][0]["path"] and "malformed XML" in d["failures"][0]["error"]
    for name in ("run1", "run2", "run3"):
        rec = aveas_format.open(tmp_path / "out" / f"{name}.aveas")
        assert rec.states.num_rows == 11
    assert rep.exit_code() == 3


def test_cli_convert_each(sources, tmp_path):
    src, m = sources
    (src / "broken.xml").unlink()
    out = tmp_path / "many"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "sumo-fcd",
                          "--each", *map(str, sorted(src.iterdir())), "--map", str(m), "-o",
                          str(out), "-j", "1", "-O", "partner=test", "-O", "license=CC-BY-4.0"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout)
    assert summary["completed"] == 3 and summary["failed"] == 0
    assert sorted(p.name for p in out.iterdir()) == ["run1.aveas", "run2.aveas", "run3.aveas"]
