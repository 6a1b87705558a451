"""OpenSCENARIO export (validated against the official XSD) and import of the timed polylines."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from lxml import etree

import aveas_format
from aveas_format.converters import convert, get_converter


def _xsd(version: str) -> etree.XMLSchema:
    sg = pytest.importorskip("scenariogeneration")
    name = {"1.2": "OpenSCENARIO_1_2.xsd", "1.3": "OpenSCENARIO_1_3_1.xsd"}[version]
    for base in (Path(sg.__file__).parent.parent / "schemas", Path(sg.__file__).parent / "schemas"):
        if (base / name).is_file():
            return etree.XMLSchema(etree.parse(str(base / name)))
    pytest.skip("the OpenSCENARIO XSD of scenariogeneration was not found")


@pytest.mark.parametrize("version", ["1.2", "1.3"])
def test_export_validates_against_xsd(rich, tmp_path, version):
    out = tmp_path / "rec.xosc"
    paths = get_converter("openscenario", "export")(rich, out, options={"version": version})
    assert [p.name for p in paths] == ["rec.xosc", "rec.xodr"]
    doc = etree.parse(str(out))
    schema = _xsd(version)
    assert schema.validate(doc), schema.error_log
    root = doc.getroot()
    assert root.find("FileHeader").get("revMinor") == version[-1]
    assert root.find("RoadNetwork/LogicFile").get("filepath") == "rec.xodr"
    ents = root.findall("Entities/ScenarioObject")
    assert len(ents) == len(np.unique(rich.states.column("participant_id").to_numpy()))
    assert len(root.findall(".//FollowTrajectoryAction")) == len(ents)
    veh = ents[0].find("Vehicle")
    assert veh is not None and veh.get("vehicleCategory") in ("car", "van", "truck")


def test_window_participants_and_lane_positions(rich, tmp_path):
    ids = sorted(set(rich.states.column("participant_id").to_pylist()))[:2]
    out = tmp_path / "w.xosc"
    get_converter("openscenario", "export")(rich, out, options={
        "time_start": 1.0, "time_end": 2.0, "participants": ids, "positions": "lane",
        "max_rate_hz": None})
    doc = etree.parse(str(out))
    assert _xsd("1.2").validate(doc)
    root = doc.getroot()
    assert [e.get("name") for e in root.findall("Entities/ScenarioObject")] == [f"p{q}" for q in ids]
    vt = [float(v.get("time")) for v in root.iter("Vertex")]
    assert min(vt) == pytest.approx(0.0) and max(vt) == pytest.approx(1.0)
    assert root.find(".//Vertex/Position/LanePosition") is not None
    back = convert("openscenario", [out])
    s = rich.states.filter(np.isin(rich.states.column("participant_id").to_numpy(), ids)
                           & (rich.states.column("time").to_numpy() >= 1.0 - 1e-9)
                           & (rich.states.column("time").to_numpy() <= 2.0 + 1e-9))
    # lane positions come back through the map: within the lateral offset precision (the samples
    # the replay fills into the sensor outage aside)
    bs = back.states.filter(pc.invert(pc.fill_null(back.states.column("interpolated"), False)))
    assert np.allclose(bs.column("x").to_numpy(), s.column("x").to_numpy(), atol=1e-6)
    assert np.allclose(bs.column("y").to_numpy(), s.column("y").to_numpy(), atol=1e-6)


def test_round_trip_of_trajectories(rich, tmp_path):
    out = tmp_path / "rt.xosc"
    get_converter("openscenario", "export")(rich, out, options={"max_rate_hz": None})
    back = convert("openscenario", [out])  # the LogicFile is found next to it
    assert aveas_format.validate(back).counts["error"] == 0
    s = rich.states
    t0 = s.column("time").to_numpy().min()
    filled = back.states.column("interpolated").to_numpy(zero_copy_only=False)
    bs = back.states.filter(pa.array(~filled))
    assert bs.num_rows == s.num_rows  # every sample a vertex, every vertex a sample
    assert np.array_equal(bs.column("participant_id").to_numpy(), s.column("participant_id").to_numpy())
    assert np.allclose(bs.column("time").to_numpy(), s.column("time").to_numpy() - t0)
    for c in ("x", "y", "heading"):
        assert np.allclose(bs.column(c).to_numpy(), s.column(c).to_numpy()), c
    # the recording's 0.5 s sensor outage (1.4 s .. 1.9 s at 10 Hz): a simulator moves the
    # entities on between the vertices, the replay samples that at the vertices' step, flagged
    gap = back.states.filter(pa.array(filled))
    assert set(np.round(gap.column("time").to_numpy(), 6)) == {1.5, 1.6, 1.7, 1.8}
    assert gap.num_rows == 4 * len(set(gap.column("participant_id").to_pylist()))
    q = gap.column("participant_id")[0].as_py()
    one = back.states.filter(pc.equal(back.states.column("participant_id"), q))
    t, x = one.column("time").to_numpy(), one.column("x").to_numpy()
    before, after = np.searchsorted(t, 1.4 - 1e-9), np.searchsorted(t, 1.9 - 1e-9)
    line = x[before] + (t[before + 1:after] - 1.4) / 0.5 * (x[after] - x[before])
    assert np.allclose(x[before + 1:after], line)
    assert not any(f.code == "time.gap" for f in aveas_format.validate(back).findings())
    p, bp = rich.participants.to_pylist(), back.participants.to_pylist()
    with_states = set(s.column("participant_id").to_pylist())
    p = [r for r in p if r["participant_id"] in with_states]
    assert [r["class"] for r in bp] == [r["class"] for r in p]
    assert [r["source_id"] for r in bp] == [r["source_id"] for r in p]
    assert np.allclose([r["length"] for r in bp], [r["length"] for r in p])
    assert back.meta.provenance.value == "simulated"


def test_esmini_replay_if_available(rich, tmp_path):
    esmini = shutil.which("esmini")
    if esmini is None:
        pytest.skip("esmini is not installed (not on PyPI or Debian; see docs/interop.md)")
    out = tmp_path / "e.xosc"
    get_converter("openscenario", "export")(rich, out)
    res = subprocess.run([esmini, "--headless", "--osc", str(out), "--fixed_timestep", "0.1"],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stdout + res.stderr


def test_cli(rich, tmp_path):
    rec_path = rich.write(tmp_path / "r.aveas")
    out = tmp_path / "r.xosc"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "export", "--to", "openscenario",
                          str(rec_path), "-o", str(out), "-O", "time_end=1.5"], capture_output=True,
                         text=True)
    assert res.returncode == 0, res.stderr
    back = tmp_path / "back.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "openscenario",
                          str(out), "-o", str(back), "-O", "license=CC-BY-4.0"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr + res.stdout
