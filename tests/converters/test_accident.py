"""Accident reconstruction (PCM-style tables) -> recording with a map built from the road lines:
a car at 10 m/s hits a pedestrian crossing at 2 m/s (analytic first contact at t = 3 s)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.converters.accident import polyline_road_geometries

RATE = 100.0
STEPS = 351


def write_case(d, *, case=True, roads=None):
    d.mkdir(parents=True, exist_ok=True)
    (d / "participants.csv").write_text(
        "participant_id,type,length,width,height,mass\n1,passenger car,4.5,1.8,1.45,1350\n"
        "2,pedestrian,0.5,0.5,1.75,75\n")
    lines = ["participant_id,step,x,y,vx,vy,ax,ay,yaw"]
    for k in range(STEPS):
        t = k / RATE
        lines.append(f"1,{k},{-30 + 10 * t:.4f},-1.75,10,0,0,0,0")
        lines.append(f"2,{k},2.5,{5 - 2 * t:.4f},0,-2,0,0,-90")
    (d / "dynamics.csv").write_text("\n".join(lines) + "\n")
    if roads is None:
        xs = np.linspace(-60, 60, 7)
        rows = ["road_id,line_id,kind,seq,x,y"]
        for lid, kind, yy in (("c", "reference", 0.0), ("l", "edge", 3.5), ("r", "edge", -3.5)):
            rows += [f"1,{lid},{kind},{i},{x},{yy}" for i, x in enumerate(xs)]
        roads = "\n".join(rows) + "\n"
    (d / "roads.csv").write_text(roads)
    if case:
        (d / "case.csv").write_text("case_id,collision_step,collision_participants,position_tol_m,"
                                    "velocity_tol_m_s,yaw_tol_deg\nA-0042,300,1;2,0.3,0.4,2.0\n")
    return d


def test_registered():
    c = load_converters()["accident"]
    assert not c.needs_map and c.method == "accident_reconstruction"


def test_case(tmp_path):
    d = write_case(tmp_path / "case")
    rec = convert("accident", [d])
    p, s = rec.participants, rec.states
    assert p.column("class").to_pylist() == ["car", "pedestrian"]
    assert p.column("source_id").to_pylist() == ["1", "2"]
    assert '"mass": 1350' in p.column("attributes")[0].as_py()
    assert s.num_rows == 2 * STEPS
    assert rec.meta.nominal_rate_hz == pytest.approx(100.0)
    assert rec.meta.provenance.value == "natural"
    h = s.column("heading").to_numpy()
    assert np.allclose(h[s.column("participant_id").to_numpy() == 1], -math.pi / 2)
    assert s.column("x_std").to_numpy() == pytest.approx(0.3 / 1.959964)
    assert s.column("vx_std").to_numpy() == pytest.approx(0.4 / 1.959964)
    assert s.column("heading_std").to_numpy() == pytest.approx(math.radians(2.0) / 1.959964)
    ev = rec.table("events")
    assert ev.column("kind").to_pylist() == ["accident"]
    assert ev.column("time_start").to_pylist() == [pytest.approx(3.0)]
    assert ev.column("participant_ids").to_pylist() == [[0, 1]]
    assert ev.column("origin").to_pylist() == ["annotated"]
    # the map: one road, one lane each side of the reference line, the car in lane -1
    car = s.column("participant_id").to_numpy() == 0
    assert s.column("lane_id").to_numpy()[car].tolist() == [-1] * STEPS
    assert s.column("road_t").to_numpy()[car] == pytest.approx(-1.75, abs=1e-6)
    report = aveas_format.validate(rec.write(tmp_path / "acc.aveas"))
    assert report.counts["error"] == 0, report


def test_collision_derived_from_footprints(tmp_path):
    d = write_case(tmp_path / "case", case=False)
    rec = convert("accident", sorted(d.iterdir()), options={"position_tol_m": 1.0})
    ev = rec.table("events")
    assert ev.column("origin").to_pylist() == ["derived"]
    assert ev.column("time_start")[0].as_py() == pytest.approx(3.0, abs=0.011)
    assert rec.states.column("x_std").to_numpy() == pytest.approx(1.0 / 1.959964)


def test_curved_reference_line_is_followed():
    """A 60-degree arc of radius 100 m given as a coarse polyline: the fitted chain of arcs stays
    within the polyline's own chord error."""
    a = np.linspace(0, math.pi / 3, 13)
    pts = np.c_[100 * np.sin(a), 100 * (1 - np.cos(a))]
    geoms, length = polyline_road_geometries(pts, step=2.0)
    assert length == pytest.approx(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    for g0, g1 in zip(geoms[:-1], geoms[1:]):  # G1: each piece starts where the last ended
        k = g0.params.get("curvature", 0.0)
        h1 = g0.hdg + k * g0.length
        assert g1.hdg == pytest.approx(h1)
    ends = np.array([[g.x, g.y] for g in geoms])
    r = np.hypot(ends[:, 0], ends[:, 1] - 100)
    chord_err = 100 * (1 - math.cos(math.pi / 3 / 12 / 2))
    assert np.abs(r - 100).max() < chord_err + 0.05


def test_curved_road_map(tmp_path):
    a = np.linspace(-0.3, 0.3, 9)
    rows = ["road_id,line_id,kind,seq,x,y"]
    for lid, kind, rr in (("ref", "reference", 200.0), ("m", "lane_marking", 196.5), ("e", "edge", 193.0),
                          ("o", "edge", 203.5)):
        rows += [f"7,{lid},{kind},{i},{rr * math.sin(t):.4f},{200 - rr * math.cos(t):.4f}"
                 for i, t in enumerate(a)]
    d = write_case(tmp_path / "c2", roads="\n".join(rows) + "\n")
    rec = convert("accident", [d])
    road = rec.map.roads["7"]
    ls = road.lane_sections[0]
    assert [ln.id for ln in ls.left] == [1, 2] and [ln.id for ln in ls.right] == [-1]
    assert [float(ln.widths[0, 1]) for ln in ls.left] == pytest.approx([3.5, 3.5], abs=0.05)
    assert float(ls.right[0].widths[0, 1]) == pytest.approx(3.5, abs=0.05)


def test_malformed_inputs_are_located(tmp_path):
    d = write_case(tmp_path / "bad")
    (d / "roads.csv").unlink()
    with pytest.raises(aveas_format.FormatError, match=r"lacks its roads.csv"):
        convert("accident", [d])
    d = write_case(tmp_path / "bad2")
    text = (d / "dynamics.csv").read_text().splitlines()
    text[4] = "2,1,2.5,oops,0,-2,0,0,-90"
    (d / "dynamics.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(aveas_format.FormatError, match=r"dynamics.csv: line 5: column 'y': 'oops' is not a number"):
        convert("accident", [d])
    d = write_case(tmp_path / "bad3")
    (d / "participants.csv").write_text("participant_id,type,length,width\n1,car,4.5,1.8\n2,pedestrian,0,0.5\n")
    with pytest.raises(aveas_format.FormatError, match=r"participants.csv: line 3: column 'length': value must be positive"):
        convert("accident", [d])
    d = write_case(tmp_path / "bad4")
    (d / "participants.csv").write_text("participant_id,type,length,width\n1,car,4.5,1.8\n")
    with pytest.raises(aveas_format.FormatError, match=r"dynamics.csv: line 3: participant_id '2' is not in participants.csv"):
        convert("accident", [d])
    d = write_case(tmp_path / "bad5", roads="road_id,line_id,kind,seq,x,y\n1,e,edge,0,0,0\n1,e,edge,1,10,0\n")
    with pytest.raises(aveas_format.FormatError, match=r"roads.csv: road '1' has no reference line"):
        convert("accident", [d])
    d = write_case(tmp_path / "bad6", roads="road_id,line_id,kind,seq,x,y\n")  # (found by make fuzz)
    with pytest.raises(aveas_format.FormatError, match=r"roads.csv: no road lines"):
        convert("accident", [d])
