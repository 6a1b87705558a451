"""SUMO FCD -> recording, on the real SUMO test excerpts (../shared/data/sumo/)."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters

from helpers_common import realdata_fixture, shared
from helpers_realdata import sumo_excerpt_map


@pytest.fixture(scope="module")
def westward_map(tmp_path_factory):
    """A one-lane road under the excerpts' vehicle: it drives west along y = 401.65."""
    p = tmp_path_factory.mktemp("maps") / "west.xodr"
    p.write_text(sumo_excerpt_map("cartesian"))
    return p


@pytest.fixture(scope="module")
def geo_map(tmp_path_factory):
    """A wide lane for the geo excerpt, in a local frame centred on its first sample."""
    p = tmp_path_factory.mktemp("maps") / "geo.xodr"
    p.write_text(sumo_excerpt_map("geo"))
    return p


def test_registered():
    assert "sumo-fcd" in load_converters()


def test_cartesian_excerpt(westward_map, tmp_path, sumo_data):
    rec = convert("sumo-fcd", [sumo_data / "fcd_cartesian_excerpt.xml"], map_source=westward_map)
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == ["0", "1"]
    assert p.column("class").to_pylist() == ["car", "car"]  # t1/t2 undefined -> passenger defaults
    assert p.column("length").to_pylist() == [5.0, 5.0]
    pid = s.column("participant_id").to_numpy()
    assert (np.bincount(pid) == [8, 3]).all()
    x = s.column("x").to_numpy()
    # front bumper (1495.25, 401.65) heading west -> centre 2.5 m further east
    assert x[0] == pytest.approx(1497.75) and x[8] == pytest.approx(1497.75)
    assert np.diff(x[:8]) == pytest.approx(-10.0) and np.diff(x[8:]) == pytest.approx(-9.0)
    assert np.allclose(s.column("y").to_numpy(), 401.65)
    assert np.allclose(s.column("heading").to_numpy(), math.pi)
    assert s.column("vx").to_pylist() == pytest.approx([-10.0] * 8 + [-9.0] * 3)
    assert np.allclose(s.column("vy").to_numpy(), 0, atol=1e-9)
    assert s.column("lane_id").to_pylist() == [-1] * 11
    assert s.column("road_s").to_numpy() == pytest.approx(1600 - x)
    assert rec.meta.provenance.value == "simulated"
    assert rec.meta.source.converter == "sumo-fcd"
    assert rec.meta.source.inputs[0].file == "fcd_cartesian_excerpt.xml"
    assert rec.meta.nominal_rate_hz == pytest.approx(1.0)
    out = rec.write(tmp_path / "fcd.aveas")
    assert aveas_format.validate(out).counts["error"] == 0


def test_vtypes_and_net_offset(westward_map, tmp_path, sumo_data):
    rou = tmp_path / "types.rou.xml"
    rou.write_text('<routes>\n  <vType id="t1" vClass="truck" length="12" width="2.5"/>\n</routes>')
    rec = convert("sumo-fcd", [sumo_data / "fcd_cartesian_excerpt.xml"], map_source=westward_map,
                  options={"vtypes": [str(rou)], "net_offset": [100.0, 0.0]})
    assert rec.participants.column("class").to_pylist() == ["truck", "car"]
    assert rec.participants.column("width").to_pylist() == [2.5, 1.8]
    assert rec.states.column("x").to_pylist()[0] == pytest.approx(1495.25 - 100 + 6.0)


def test_net_file_offset(westward_map, tmp_path, sumo_data):
    net = tmp_path / "n.net.xml"
    net.write_text('<net>\n <location netOffset="-10.00,2.50" convBoundary="0,0,1,1"/>\n</net>')
    rec = convert("sumo-fcd", [sumo_data / "fcd_cartesian_excerpt.xml"], map_source=westward_map,
                  options={"net_file": str(net)})
    assert rec.states.column("x").to_pylist()[0] == pytest.approx(1495.25 + 10 + 2.5)
    assert rec.states.column("y").to_pylist()[0] == pytest.approx(401.65 - 2.5)


def test_geo_excerpt_is_detected_and_projected(geo_map, sumo_data):
    rec = convert("sumo-fcd", [sumo_data / "fcd_geo_excerpt.xml"], map_source=geo_map)
    s = rec.states
    x, y = s.column("x").to_numpy(), s.column("y").to_numpy()
    assert x[0] == pytest.approx(2.5, abs=0.05) and abs(y[0]) < 0.05
    assert np.hypot(np.diff(x[:8]), np.diff(y[:8])) == pytest.approx(10.0, abs=0.1)  # 1e-6 deg ~ 7 cm
    assert np.hypot(np.diff(x[8:]), np.diff(y[8:])) == pytest.approx(9.0, abs=0.1)
    assert s.column("lane_id").to_pylist() == [-1] * 11


def test_parquet_variant_equals_xml(westward_map, tmp_path, sumo_data):
    import pyarrow as pa
    import pyarrow.parquet as pq

    rec = convert("sumo-fcd", [sumo_data / "fcd_cartesian_excerpt.xml"], map_source=westward_map)
    n = 11
    t = np.r_[np.arange(8.0), np.arange(5.0, 8.0)]
    table = pa.table({
        "timestep_time": t, "vehicle_id": ["0"] * 8 + ["1"] * 3,
        "vehicle_x": np.r_[1495.25 - 10 * np.arange(8), 1495.25 - 9 * np.arange(3)],
        "vehicle_y": np.full(n, 401.65), "vehicle_angle": np.full(n, 270.0),
        "vehicle_type": ["t1"] * 8 + ["t2"] * 3, "vehicle_speed": np.r_[np.full(8, 10.0), np.full(3, 9.0)]})
    pq.write_table(table, tmp_path / "fcd.parquet")
    rec2 = convert("sumo-fcd", [tmp_path / "fcd.parquet"], map_source=westward_map)
    assert np.allclose(rec2.states.column("x").to_numpy(), rec.states.column("x").to_numpy())


@pytest.mark.parametrize("text,match", [
    ('<fcd-export>\n<timestep time="0">\n<vehicle id="a" x="1" y="2" angle="0"\n</fcd-export>',
     r"bad.xml: line \d+: malformed XML"),
    ('<fcd-export>\n<timestep time="0">\n  <vehicle id="a" x="1" angle="0"/>\n</timestep>\n</fcd-export>',
     r"bad.xml: line 3: <vehicle id='a'> lacks attribute 'y'"),
    ('<fcd-export>\n<timestep time="0">\n  <vehicle id="a" x="one" y="1" angle="0"/>\n</timestep>\n'
     '</fcd-export>', r"bad.xml: line 3: <vehicle id='a'>: could not convert"),
    ('<fcd-export>\n</fcd-export>', r"bad.xml: no <vehicle> or <person> samples"),
])
def test_malformed_input_is_located(westward_map, tmp_path, text, match):
    bad = tmp_path / "bad.xml"
    bad.write_text(text)
    with pytest.raises(aveas_format.FormatError, match=match):
        convert("sumo-fcd", [bad], map_source=westward_map)


def test_cli_convert(westward_map, tmp_path, sumo_data):
    out = tmp_path / "cli.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "sumo-fcd",
                          str(sumo_data / "fcd_cartesian_excerpt.xml"), "--map", str(westward_map),
                          "-o", str(out), "-O", "net_offset=[0,0]", "-O", "partner=test", "-O",
                          "license=CC-BY-4.0"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "valid" in res.stderr and out.is_dir()
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "nope",
                          "x.xml", "-o", str(tmp_path / "y.aveas")], capture_output=True, text=True)
    assert res.returncode == 2 and "no import converter named 'nope'" in res.stderr
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "sumo-fcd",
                          str(sumo_data / "fcd_cartesian_excerpt.xml"), "--map", str(westward_map),
                          "-o", str(tmp_path / "z.aveas"), "-O", "colour=red"], capture_output=True,
                         text=True)
    assert res.returncode == 2
    assert "invalid options: colour: Extra inputs are not permitted" in res.stderr


@realdata_fixture(scope="module")
def road():
    """netconvert's map of ../shared/data/real/sumo: 3 lanes of 3.2 m along +x."""
    return shared("data", "real", "sumo", "road.xodr")


def _fcd(rows):
    steps = {}
    for t, vid, x, y, angle, speed, lat in rows:
        attrs = f'x="{x:.2f}" y="{y:.2f}" angle="{angle:.2f}" type="car" speed="{speed:.2f}"'
        if lat is not None:
            attrs += f' speedLat="{lat:.2f}"'
        steps.setdefault(t, []).append(f'<vehicle id="{vid}" {attrs}/>')
    body = "".join(f'<timestep time="{t:.2f}">{"".join(v)}</timestep>' for t, v in sorted(steps.items()))
    return f'<?xml version="1.0"?><fcd-export>{body}</fcd-export>'


def test_lane_change_instant_and_reconstructed(road, tmp_path):
    """One car jumps a lane width (3.2 m) in one 0.5-s step (SUMO's default): validate reports one
    instant_lane_change; with lane_change_duration=3 the positions move across smoothly, the
    velocity carries the lateral speed, the heading turns with it, and nothing is reported."""
    rows = []
    for k in range(40):
        t = 0.5 * k
        rows.append((t, "a", 10.0 + 15.0 * t, -8.0 if t < 10.0 else -4.8, 90.0, 15.0, None))
    p = tmp_path / "fcd.xml"
    p.write_text(_fcd(rows))
    rec = convert("sumo-fcd", [p], map_source=road)
    rep = aveas_format.validate(rec, select=["kinematics"])
    assert rep.codes == {"kinematics.instant_lane_change"}
    assert "jumps up to 3.2 m across the lane in 0.5 s" in rep.findings()[0].message
    rec = convert("sumo-fcd", [p], map_source=road, options={"lane_change_duration": 3.0})
    assert aveas_format.validate(rec, select=["kinematics"]).codes == set()
    s = rec.states
    t, y, vy, h = (s.column(c).to_numpy() for c in ("time", "y", "vy", "heading"))
    assert np.all(np.diff(y) >= -1e-9) and y[0] == pytest.approx(-8.0) and y[-1] == pytest.approx(-4.8)
    mid = (y[t == 9.5][0] + y[t == 10.0][0]) / 2  # the jump's time lies between: half-way there
    assert abs(mid - (-6.4)) < 0.05
    u = np.clip((t - (9.75 - 1.5)) / 3.0, 0, 1)  # the quintic over 3 s centred on the jump
    assert np.allclose(vy, 3.2 * 30 * u ** 2 * (1 - u) ** 2 / 3.0, atol=1e-6)  # peak 2.0 m/s
    assert np.allclose(s.column("vx").to_numpy(), 15.0)  # the speed stays along the lane
    assert h.max() == pytest.approx(np.arctan2(vy.max(), 15.0), rel=0.02)
    assert rec.meta.source.options["lane_changes_reconstructed"] == 1
    assert '"reconstructed_lane_changes": 1' in rec.participants.column("attributes")[0].as_py()


def test_speed_lat_is_the_lateral_speed(road, tmp_path):
    """SUMO's speed is along the lane, speedLat across it: the velocity is their sum, whatever
    the FCD angle (which includes the lateral motion)."""
    rows = []
    y = -8.0
    for k in range(20):
        t = 0.5 * k
        lat = 1.0 if 2.0 <= t < 5.0 else 0.0
        ang = 90.0 - np.degrees(np.arctan2(lat, 20.0))
        rows.append((t, "b", 10.0 + 20.0 * t, y, ang, 20.0, lat))
        y += 0.5 * lat
    p = tmp_path / "fcd.xml"
    p.write_text(_fcd(rows))
    rec = convert("sumo-fcd", [p], map_source=road)
    s = rec.states
    assert np.allclose(s.column("vx").to_numpy(), 20.0)  # not 20 cos(theta)
    lat = np.array([r[6] for r in rows])
    assert np.allclose(s.column("vy").to_numpy(), lat)
    assert rec.meta.source.options["lateral_speed"].startswith("speedLat")
