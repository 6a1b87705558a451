"""Every real ASAM OSI trace under ../shared/data (omega-prime's, written by esmini): it converts
on its map, validates without errors, exports to OpenLABEL / OpenSCENARIO / OSI and imports back
with the same motion, and is plausible against the trace (objects and frames, positions on the map,
speeds, sizes). And the frame where the map has no geoReference (issue 18, point 1): the trace's
proj_string, ``--crs``, and an error that shows a command that works."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
import warnings

import numpy as np
import pytest

import aveas_format
from aveas_format.converters.registry import convert
from helpers_realdata import DATA, REAL, SOME_CRS, assert_same_motion, real_files, round_trips

TRACES = real_files("real/**/*.osi")

#: which map each trace was written on (omega-prime's mapping.json is not handed out; its own tests
#: pair alks_cut-in with straight_500m, as the trace's positions do: x 31..222 m, y +-1.5 m)
MAP_OF = {"alks_cut-in.osi": "straight_500m.xodr", "acc-test.osi": "straight_500m.xodr",
          "pedestrian.osi": "fabriksgatan.xodr"}


#: what only a person can state, which convert asks for (the sources here do not carry it)
STATED = ("-O", "partner=test", "-O", "license=CC0-1.0")

def _map(path):
    name = MAP_OF.get(path.name)
    found = [p for p in DATA.rglob(name or "-")] if name else []
    if not found:
        pytest.skip(f"no map known for {path.name}")
    return next((p for p in found if p.parent == path.parent), found[0])


def _frames(path) -> int:
    import betterosi

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return sum(1 for _ in betterosi.read(str(path), return_ground_truth=True))


@pytest.mark.parametrize("path", TRACES)
def test_converts_validates_and_is_plausible(path, shared_data):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = convert("osi", [path], map_source=_map(path))
    report = aveas_format.validate(rec)
    assert report.counts["error"] == 0, report.flatten(("code", "message"))
    s = rec.states
    # one state per object and frame: as many distinct times as GroundTruth messages
    assert len(np.unique(s["time"].to_numpy())) == _frames(path)
    assert rec.participants.num_rows >= 1
    on_map = 1 - s["road_id"].null_count / s.num_rows
    assert on_map > 0.95
    speed = np.hypot(s["vx"].to_numpy(), s["vy"].to_numpy())
    assert speed.max() < 70.0
    for p in rec.participants.to_pylist():
        if p["class"] == "car":
            assert 3.0 < p["length"] < 6.0 and 1.4 < p["width"] < 2.5


@pytest.mark.parametrize("path", TRACES)
def test_exports_and_imports_back(path, shared_data, tmp_path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = convert("osi", [path], map_source=_map(path))
    for name, back in round_trips(rec, tmp_path).items():
        assert_same_motion(rec, back, tol_m=1e-3 if name != "openlabel" else 1e-2)


def _without_georeference(src, dst):
    text = re.sub(r"<geoReference>.*?</geoReference>", "", src.read_text(), flags=re.S)
    dst.write_text(text)
    return dst


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_alks_cut_in_on_the_wrong_map_is_an_error(shared_data, tmp_path):
    """Issue 18, point 7 on a real trace: alks_cut-in on e6mini (a highway along y; the trace runs
    along x) converted "valid" before; now the conversion ends in map.mostly_off_road."""
    trace = REAL / "omega-prime" / "alks_cut-in.osi"
    r = _cli("convert", "--from", "osi", trace, "--map", REAL / "omega-prime" / "e6mini.xodr",
             "-o", tmp_path / "w.aveas", *STATED)
    assert r.returncode == 1 and "0.0% on the map" in r.stderr
    assert "map.mostly_off_road" in r.stdout and "are on no road of the map" in r.stdout


def test_alks_cut_in_on_a_map_without_georeference(shared_data, tmp_path):
    """``convert --from osi alks_cut-in.osi --map straight_500m.xodr --crs ...`` with the map's
    geoReference removed (as in 3 of 4 public maps). The trace's proj_string gives the frame by
    itself; ``--crs`` overrides it; with the map's geoReference, ``--crs`` must agree with it."""
    trace = REAL / "omega-prime" / "alks_cut-in.osi"
    e6 = REAL / "omega-prime" / "straight_500m.xodr"
    bare = _without_georeference(e6, tmp_path / "straight_500m.xodr")
    out = tmp_path / "a.aveas"
    r = _cli("convert", "--from", "osi", trace, "--map", bare, "--crs", SOME_CRS, "-o", out, *STATED)
    assert r.returncode == 0, r.stderr + r.stdout
    rec = aveas_format.open(out)
    assert rec.meta.crs == SOME_CRS and rec.map.header.geo_reference is None
    r = _cli("convert", "--from", "osi", trace, "--map", bare, "-o", tmp_path / "b.aveas", *STATED)
    assert r.returncode == 0, r.stderr + r.stdout  # the trace's proj_string is the frame
    # the map has a geoReference: --crs must agree
    r = _cli("convert", "--from", "osi", trace, "--map", e6, "--crs", SOME_CRS, "-o", tmp_path / "c", *STATED)
    assert r.returncode != 0 and "differs from the map's <geoReference>" in r.stderr
    # OSI export of the recording on the bare map: the map travels with the trace, with the crs
    # as its geoReference, and the trace re-imports with nothing else
    r = _cli("export", "--to", "osi", out, "-o", tmp_path / "x.osi")
    assert r.returncode == 0, r.stderr
    assert "wrote " + str(tmp_path / "x.xodr") in r.stderr
    r = _cli("export", "--to", "osi", out, "-o", tmp_path / "x.osi")
    assert r.returncode == 2 and "pass --overwrite" in r.stderr  # companion files are outputs
    (tmp_path / "x.osi").unlink()
    r = _cli("export", "--to", "osi", out, "-o", tmp_path / "x.osi")
    assert r.returncode == 0 and "kept " + str(tmp_path / "x.xodr") in r.stderr  # the same map
    (tmp_path / "x.osi").unlink()
    (tmp_path / "x.xodr").write_bytes((tmp_path / "x.xodr").read_bytes() + b"\n")
    r = _cli("export", "--to", "osi", out, "-o", tmp_path / "x.osi")
    assert r.returncode == 2 and "x.xodr: exists" in r.stderr  # ... another map is not replaced
    r = _cli("export", "--to", "osi", out, "-o", tmp_path / "x.osi", "--overwrite")
    assert r.returncode == 0, r.stderr
    back = convert("osi", [tmp_path / "x.osi"])  # its map_reference names x.xodr
    assert back.meta.crs == SOME_CRS
    assert_same_motion(rec, back)


def test_missing_crs_error_shows_a_command_that_works(shared_data, tmp_path):
    """A map without geoReference and a source without a frame of its own (an OpenSCENARIO file):
    the error shows the command with --crs, and that command (with the site's coordinates)
    converts."""
    src = REAL / "esmini" / "resources" / "xosc" / "pedestrian_traj_synch.xosc"
    r = _cli("convert", "--from", "openscenario", src, "-o", tmp_path / "p.aveas", *STATED)
    assert r.returncode != 0
    msg = r.stderr.strip().splitlines()[-1]
    assert "the map has no <geoReference>" in msg, msg
    cmd = re.search(r"(aveas-format convert .*? -o OUT\.aveas)", msg).group(1)
    args = shlex.split(cmd)[1:]
    args[args.index("OUT.aveas")] = str(tmp_path / "p.aveas")
    r = _cli(*args)
    assert r.returncode == 0, r.stderr + r.stdout
    assert aveas_format.open(tmp_path / "p.aveas").meta.crs.startswith("+proj=tmerc")


@pytest.mark.parametrize("path", TRACES)
def test_validate_the_trace_as_submitted(path, shared_data, capsys):
    """``aveas-format validate TRACE --map MAP`` (issue 22): imported on the fly, the format's
    rules and the source.osi.* rules run, no error; esmini's traces have no OSI finding."""
    import json

    from aveas_format.cli.app import app
    from aveas_format.cli.common import run

    code = run(app, ["validate", str(path), "--map", str(_map(path)), "--format", "json"])
    rep = json.loads(capsys.readouterr().out)
    assert code == 0 and rep["recording"] == str(path) and not rep["failures"]
    assert {"source.osi.missing_dimension", "kinematics.speed"} <= set(rep["rules_run"])
    assert not [r["code"] for r in rep["results"] if r["code"].startswith("source.osi.")]
