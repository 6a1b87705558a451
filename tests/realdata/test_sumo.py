"""SUMO floating-car data other runs wrote: the excerpts of SUMO's own tests (../shared/data/sumo)
and a default run with instantaneous lane changes (../shared/data/real/sumo). Each converts,
validates (the default run: one instantaneous-lane-change finding per vehicle, nothing else;
reconstructed: no error), round-trips through OpenLABEL/OpenSCENARIO/OSI and is plausible against
the FCD (vehicle and step counts, positions on the map, speeds). And the velocity is SUMO's: TTC
against SUMO's own SSM device on a run with lane changes."""

from __future__ import annotations

import gzip
import json
import subprocess
from collections import defaultdict

import numpy as np
import pyarrow.compute as pc
import pytest
from lxml import etree

import aveas_format
from aveas_format.converters import convert

from helpers_realdata import (REAL, assert_plausible, assert_same_trajectories, error_codes, real_files,
                              round_trips, sumo_excerpt_map)

RUN = REAL / "sumo"


def _fcd(path):
    """Per vehicle: [(time, lane, speed, speedLat)] of an FCD file (plain or gzipped)."""
    opener = gzip.open if path.suffix == ".gz" else open
    out, t = defaultdict(list), None
    with opener(path, "rb") as f:
        for ev, el in etree.iterparse(f, events=("start", "end"), tag=("timestep", "vehicle")):
            if el.tag == "timestep":
                if ev == "start":
                    t = float(el.get("time"))
                else:
                    el.clear()
                continue
            if ev == "end":
                out[el.get("id")].append((t, el.get("lane"), float(el.get("speed")),
                                          float(el.get("speedLat") or 0.0)))
    return out


def _lane_changes(fcd) -> dict[str, int]:
    """Lane changes per vehicle in the FCD: the lane index changes between two steps."""
    n = {}
    for vid, rows in fcd.items():
        idx = [int(lane.rsplit("_", 1)[1]) for _, lane, _, _ in rows]
        k = int(np.sum(np.diff(idx) != 0))
        if k:
            n[vid] = k
    return n


def _convert(path, tmp_path, **options):
    if path.parent == RUN:
        return convert("sumo-fcd", [path], map_source=RUN / "road.xodr",
                       options={"vtypes": [RUN / "r.rou.xml"], **options})
    m = tmp_path / "map.xodr"
    m.write_text(sumo_excerpt_map("geo" if "geo" in path.name else "cartesian"))
    return convert("sumo-fcd", [path], map_source=m, options=options)


@pytest.mark.parametrize("path", real_files("sumo/*.xml", "real/sumo/*.xml.gz"))
def test_converts_validates_round_trips(path, tmp_path):
    fcd = _fcd(path)
    changes = _lane_changes(fcd)
    rec = _convert(path, tmp_path)
    # counts and positions against the FCD
    assert rec.participants.num_rows == len(fcd)
    assert rec.states.num_rows == sum(len(v) for v in fcd.values())
    assert rec.states.column("road_id").null_count == 0  # every state on the map
    # SUMO's speed is along the lane: without lateral motion the velocity's norm is the speed
    speed = np.hypot(rec.states.column("vx").to_numpy(), rec.states.column("vy").to_numpy())
    sid = dict(enumerate(rec.participants.column("source_id").to_pylist()))
    fcd_speed = {(vid, t): v for vid, rows in fcd.items() for t, _, v, _ in rows}
    want = [fcd_speed[(sid[p], t)] for p, t in zip(rec.states.column("participant_id").to_pylist(),
                                                   rec.states.column("time").to_pylist())]
    np.testing.assert_allclose(speed, want, atol=0.02)  # 2-decimal positions: lateral noise only
    assert_plausible(rec)
    if changes:  # the default run: one finding per vehicle that changed lanes, each change counted
        assert error_codes(rec) == {"kinematics.instant_lane_change"}
        found = [f for f in aveas_format.validate(rec).findings()
                 if f.code == "kinematics.instant_lane_change"]
        assert {sid[f.location.participant_id] for f in found} == set(changes)
        assert all("--lanechange.duration" in f.message for f in found)
        rec = _convert(path, tmp_path, lane_change_duration=3.0)
        assert rec.meta.source.options["lane_changes_reconstructed"] == sum(changes.values())
        attrs = {s: json.loads(a) for s, a in zip(rec.participants.column("source_id").to_pylist(),
                                                  rec.participants.column("attributes").to_pylist())}
        assert {s for s, a in attrs.items() if a.get("reconstructed_lane_changes")} == set(changes)
    assert error_codes(rec) == set()
    for fmt, back in round_trips(rec, tmp_path).items():
        assert_same_trajectories(rec, back, f"{path.name} via {fmt}")


def test_velocity_as_sumo_defines_it_against_ssm(sumo, shared_data, tmp_path):
    """SUMO on the run's inputs with 3-s lane changes (lateral motion, speedLat in the FCD) and the
    SSM device as the oracle: the converter's velocity is the speed along the lane plus speedLat
    across it, so the lane-1D TTC of following pairs agrees with SSM's during lane changes as well
    as elsewhere (speed along the FCD angle was short by v(1 - cos theta): 0.4 % median there)."""
    from aveas_format.derive import derive

    net = tmp_path / "road.net.xml"
    bindir = sumo.parent
    subprocess.run([str(bindir / "netconvert"), "-n", str(RUN / "n.nod.xml"), "-e", str(RUN / "n.edg.xml"),
                    "-o", str(net), "--no-turnarounds", "--offset.disable-normalization", "true"],
                   check=True, capture_output=True)
    fcd, ssm = tmp_path / "fcd.xml", tmp_path / "ssm.xml"
    subprocess.run([str(sumo), "-n", str(net), "-r", str(RUN / "r.rou.xml"), "--step-length", "0.5",
                    "--seed", "3", "--end", "90", "--lanechange.duration", "3",
                    "--fcd-output", str(fcd), "--fcd-output.attributes", "x,y,angle,type,speed,speedLat,lane",
                    "--device.ssm.probability", "1", "--device.ssm.measures", "TTC",
                    "--device.ssm.thresholds", "20", "--device.ssm.range", "100",
                    "--device.ssm.trajectories", "true", "--device.ssm.file", str(ssm),
                    "--no-step-log", "--no-warnings"], check=True, capture_output=True)
    rec = convert("sumo-fcd", [fcd], map_source=RUN / "road.xodr", options={"vtypes": [RUN / "r.rou.xml"]})
    assert rec.meta.source.options["lateral_speed"].startswith("speedLat")
    assert error_codes(rec) == set()  # smooth lane changes: nothing to report
    derive(rec, only="interactions")
    it = rec.derived["interactions"]
    it = it.filter(pc.equal(it.column("relation"), "leader"))
    ours = {(p, o, round(t, 2)): v for p, o, t, v in zip(*(it.column(c).to_pylist() for c in
                                                           ("participant_id", "other_id", "time", "ttc")))
            if v is not None and np.isfinite(v)}
    pid = {s: i for i, s in enumerate(rec.participants.column("source_id").to_pylist())}
    lateral = {(pid[v], round(t, 2)) for v, rows in _fcd(fcd).items() for t, _, _, lat in rows if abs(lat) > 0.01}
    rel = {True: [], False: []}
    for _, c in etree.iterparse(str(ssm), tag="conflict"):
        e, f = pid[c.get("ego")], pid[c.get("foe")]
        for t, kind, ttc in zip(*(c.find(k).get("values").split() for k in ("timeSpan", "typeSpan", "TTCSpan"))):
            key = (e, f, round(float(t), 2))
            if kind == "2" and ttc != "NA" and key in ours:  # 2: ego follows foe
                during = (e, key[2]) in lateral or (f, key[2]) in lateral
                rel[during].append(abs(ours[key] - float(ttc)) / float(ttc))
        c.clear()
    during, elsewhere = np.array(rel[True]), np.array(rel[False])
    assert len(during) >= 20 and len(elsewhere) >= 100
    # 2-decimal FCD values: a 0.01 m/s rounding is 2 % of a 0.5 m/s closing speed, hence p90
    assert np.median(during) < 0.002 and np.percentile(during, 90) < 0.01, \
        (np.median(during), np.percentile(during, 90))
    assert np.median(elsewhere) < 0.002, np.median(elsewhere)
