"""Driving-simulator log -> recording (states + interior), from an analytic truth."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.opendrive.builder import straight_highway

GEO = "+proj=tmerc +lat_0=52.3 +lon_0=10.5 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
RATE = 50.0


@pytest.fixture(scope="module")
def road(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "road.xodr"
    p.write_text(straight_highway(length=1000.0, lanes_right=2, geo_reference=GEO))
    return p


def truth(n: int = 200):
    t = np.arange(n) / RATE
    T = t[-1]
    # subject: lane change from lane -1 to -2 (y -1.75 -> -5.25) at 25 m/s, rear axle logged
    y = -1.75 - 3.5 * (1 - np.cos(np.pi * t / T)) / 2
    vy = -3.5 * np.pi / T * np.sin(np.pi * t / T) / 2
    ego = dict(id="ego", x=50 + 25 * t, y=y, vx=np.full(n, 25.0), vy=vy, L=4.8, W=1.9)
    ego["heading"] = np.arctan2(vy, ego["vx"])
    lead = dict(id="veh7", x=120 + 22 * t, y=np.full(n, -5.25), vx=np.full(n, 22.0), vy=np.zeros(n),
                heading=np.zeros(n), L=12.0, W=2.5, cls="truck")
    for v in (ego, lead):
        v["t"] = t
    return ego, lead


def write_log(path, ego, lead, *, rear_axle: float = -1.4, deg: bool = False, parquet=False):
    n = len(ego["t"])
    rows = {k: [] for k in ("time", "id", "x", "y", "heading", "speed", "length", "width", "class",
                            "light_indicator_right", "steering_wheel_angle", "accelerator_pedal",
                            "brake_pedal", "gear", "automation_longitudinal", "hands_on_wheel_p",
                            "driver_focus", "driver_gaze_yaw")}
    for v, is_ego in ((ego, True), (lead, False)):
        px = v["x"] + rear_axle * np.cos(v["heading"])
        py = v["y"] + rear_axle * np.sin(v["heading"])
        h = np.degrees(v["heading"]) if deg else v["heading"]
        for i in range(n):
            rows["time"].append(float(v["t"][i]))
            rows["id"].append(v["id"])
            rows["x"].append(float(px[i]))
            rows["y"].append(float(py[i]))
            rows["heading"].append(float(h[i]))
            rows["speed"].append(float(math.hypot(v["vx"][i], v["vy"][i])))
            rows["length"].append(v["L"])
            rows["width"].append(v["W"])
            rows["class"].append(v.get("cls", "car"))
            rows["light_indicator_right"].append(1.0 if is_ego and i < n // 2 else 0.0)
            sw = 0.3 * math.sin(2 * math.pi * i / n) if is_ego else None
            rows["steering_wheel_angle"].append(math.degrees(sw) if (deg and sw is not None) else sw)
            rows["accelerator_pedal"].append(0.4 if is_ego else None)
            rows["brake_pedal"].append(0.0 if is_ego else None)
            rows["gear"].append(5 if is_ego else None)
            rows["automation_longitudinal"].append(1 if is_ego and i > n // 2 else 0)
            rows["hands_on_wheel_p"].append(1.0 if is_ego else None)
            rows["driver_focus"].append(("mirrors" if i < 20 else "road_ahead") if is_ego else None)
            rows["driver_gaze_yaw"].append(0.1 if is_ego else None)
    table = pa.table(rows)
    if parquet:
        pq.write_table(table, path)
    else:
        import pyarrow.csv as pacsv

        pacsv.write_csv(table, path)
    return path


def test_registered():
    assert "driving-simulator" in load_converters()


@pytest.mark.parametrize("deg,parquet", [(False, False), (True, True)])
def test_log_roundtrip(tmp_path, road, deg, parquet):
    ego, lead = truth()
    log = write_log(tmp_path / ("run.parquet" if parquet else "run.csv"), ego, lead, deg=deg,
                    parquet=parquet)
    rec = convert("driving-simulator", [log], map_source=road,
                  options={"reference_offset": -1.4, "angle_unit": "deg" if deg else "rad",
                           "simulator": "SILAB 7"})
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == ["ego", "veh7"]
    assert p.column("role").to_pylist() == ["recording_vehicle", "simulated_agent"]
    assert p.column("provenance").to_pylist() == ["staged", "simulated"]
    assert p.column("class").to_pylist() == ["car", "truck"]
    assert p.column("length").to_pylist() == [4.8, 12.0]
    pid = s.column("participant_id").to_numpy()
    for k, v in enumerate((ego, lead)):
        m = pid == k
        assert np.allclose(s.column("x").to_numpy()[m], v["x"], atol=1e-9)
        assert np.allclose(s.column("y").to_numpy()[m], v["y"], atol=1e-9)
        assert np.allclose(s.column("heading").to_numpy()[m], v["heading"], atol=1e-12)
        assert np.allclose(s.column("vx").to_numpy()[m], v["vx"], atol=1e-9)
        assert np.allclose(s.column("vy").to_numpy()[m], v["vy"], atol=1e-9)
    lane = np.asarray(s.column("lane_id").to_pylist())
    assert lane[pid == 0][0] == -1 and lane[pid == 0][-1] == -2
    assert np.allclose(s.column("x_std").to_numpy(), 0.0)
    ind = s.column("light_indicator_right_p").to_numpy()
    assert ind[pid == 0][:100].tolist() == [1.0] * 100
    it = rec.table("interior")
    assert it.num_rows == 200 and set(it.column("participant_id").to_pylist()) == {0}
    assert np.allclose(it.column("steering_wheel_angle").to_numpy(),
                       0.3 * np.sin(2 * np.pi * np.arange(200) / 200))
    assert it.column("gear").to_pylist()[:2] == [5, 5]
    assert it.column("automation_longitudinal_p").to_pylist()[150] == 1.0
    assert it.column("driver_focus").to_pylist()[0]["mirrors"] == 1.0
    assert it.column("driver_focus").to_pylist()[50]["road_ahead"] == 1.0
    meta = rec.meta
    assert meta.provenance.value == "mixed"
    assert meta.acquisition.method.value == "driving_simulator"
    assert meta.acquisition.platform == "SILAB 7"
    assert meta.nominal_rate_hz == pytest.approx(RATE)
    report = aveas_format.validate(rec.write(tmp_path / "sim.aveas"))
    assert report.counts["error"] == 0, report


def test_navigation_convention_and_vx_vy(tmp_path, road):
    log = tmp_path / "nav.csv"
    log.write_text("time,id,x,y,heading,vx,vy\n0,ego,10,-1.75,90,20,0\n0.1,ego,12,-1.75,90,20,0\n"
                   "0.2,ego,14,-1.75,90,20,0\n")
    rec = convert("driving-simulator", [log], map_source=road,
                  options={"heading_convention": "navigation", "angle_unit": "deg",
                           "subject_provenance": "simulated"})
    assert np.allclose(rec.states.column("heading").to_numpy(), 0.0)
    assert rec.meta.provenance.value == "simulated"
    assert rec.table("interior") is None or rec.table("interior").num_rows == 0


@pytest.mark.parametrize("text,match", [
    ("time,id,x,y,heading,speed\n0,ego,1,2,0,3\n0.1,ego,abc,2,0,3\n",
     r"run.csv: line 3: column 'x': 'abc' is not a number"),
    ("time,id,x,y,heading,speed\n0,car1,1,2,0,3\n", r"run.csv: no rows of the subject vehicle 'ego'"),
    ("time,id,x,y,heading\n0,ego,1,2,0\n", r"run.csv: the log needs 'vx' and 'vy' or 'speed'"),
    ("time,id,x,y,heading,speed\n0,ego,1,2,0,3\n0,ego,1,2,0,3\n",
     r"run.csv: line 3: participant 'ego' sampled twice at time 0.0$"),
    ("time,id,x,y,heading,speed,class\n0,ego,1,2,0,3,spaceship\n",
     r"run.csv: line 2: column 'class': 'spaceship' is not one of"),
    ("time,id,x,y,heading,speed,brake_pedal\n0,ego,1,2,0,3,0.5\n0.1,ego,1,2,0,3,7\n",
     r"run.csv: line 3: column 'brake_pedal': 7 is not a probability"),
    ("time,id,x,y,heading,speed,driver_focus\n0,ego,1,2,0,3,sky\n",
     r"run.csv: line 2: column 'driver_focus': 'sky' is not one of"),
    ("time,id,x,y,speed\n0,ego,1,2,3\n", r"run.csv: required column\(s\) \['heading'\] missing"),
])
def test_malformed_input_is_located(tmp_path, road, text, match):
    log = tmp_path / "run.csv"
    log.write_text(text)
    with pytest.raises(aveas_format.FormatError, match=match):
        convert("driving-simulator", [log], map_source=road)
