"""SUMO's SSM device as an independent oracle for the derivations (docs/derive.md "Checked against
SUMO's SSM device").

SUMO computes TTC, DRAC, MDRAC, PET, PPET, BR, SGAP and TGAP with its own code while it simulates
(``--device.ssm.*``). Running a scenario with the device on, converting its FCD into a recording,
deriving, and matching the two sample by sample (same ego, foe and time step) shows where the
measures agree and where their definitions differ.

- :func:`ssm_args`: the sumo options that equip every vehicle and log every encounter with full
  time series (thresholds wide open).
- :func:`read_ssm`: the device's XML as tables: ``encounters`` (one row per ego, foe and time
  step: encounter type, TTC, DRAC, MDRAC, PPET), ``pet`` (one row per measured PET) and
  ``globals`` (per vehicle and time step: BR, SGAP, TGAP).
- :func:`junction_scenario`: a 4-way priority junction with crossing and turning flows (the SUMO
  network from plain nodes and edges by netconvert, the recording's OpenDRIVE map exported from
  it by netconvert), run with the device and converted.
- :func:`autobahn_scenario`: the paper's autobahn through :func:`aveas_format.sim.simulate` with
  the device on.
- :func:`compare`: the matched samples and the agreement of each measure.

SUMO's encounter types used here: 2 (ego follows foe: lane follower), 10/11 (crossing, ego first
/ foe first), 6/7 (merging).
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.sim.runner import SimulationError, find_sumo, run_tool

#: every measure of SUMO's device (1.28)
SSM_MEASURES = ("TTC", "DRAC", "MDRAC", "PET", "PPET", "BR", "SGAP", "TGAP")
#: thresholds that log every encounter (TTC, PET, PPET, SGAP, TGAP below; DRAC, MDRAC, BR above)
_OPEN = {"TTC": 1e6, "DRAC": 0.0, "MDRAC": 0.0, "PET": 1e6, "PPET": 1e6, "BR": 0.0, "SGAP": 1e6,
         "TGAP": 1e6}
#: encounter types: lane follower (ego follows foe), crossing, merging
FOLLOWING_FOLLOWER = 2
CROSSING = (10, 11)
MERGING = (6, 7)


def ssm_args(file: str = "ssm.xml", *, range_m: float = 100.0, extra_time: float = 5.0,
             mdrac_prt: float = 1.0) -> list[str]:
    """sumo options: the SSM device in every vehicle, all measures with open thresholds, full
    trajectories (time series) and lane positions, written to ``file``; outputs with 6
    decimals."""
    return ["--device.ssm.probability", "1",
            "--device.ssm.measures", " ".join(SSM_MEASURES),
            "--device.ssm.thresholds", " ".join(f"{_OPEN[m]:g}" for m in SSM_MEASURES),
            "--device.ssm.range", f"{range_m:g}", "--device.ssm.extratime", f"{extra_time:g}",
            "--device.ssm.mdrac.prt", f"{mdrac_prt:g}",
            "--device.ssm.trajectories", "true", "--device.ssm.write-lane-positions", "true",
            "--device.ssm.file", file,
            # all outputs (FCD too) with 6 decimals (OUTPUT_RESOLUTION): 2 (the default) make a
            # 0.1 m/s closing speed uncertain by 10 %
            "--precision", "6"]


def _floats(text: str | None) -> np.ndarray:
    if not text:
        return np.zeros(0)
    return np.array([np.nan if v == "NA" else float(v) for v in text.split()], float)


def read_ssm(path: str | Path) -> dict[str, pa.Table]:
    """The SSM device's output: ``encounters`` (ego, foe, time, type, ttc, drac, mdrac, ppet; NaN
    where SUMO writes NA), ``pet`` (ego, foe, time, type, pet) and ``globals`` (ego, time, br,
    sgap, tgap)."""
    from aveas_format.safeio import iterparse

    enc: dict[str, list] = {k: [] for k in ("ego", "foe", "time", "type", "ttc", "drac", "mdrac",
                                            "ppet", "ego_lane", "foe_lane")}
    pet: dict[str, list] = {k: [] for k in ("ego", "foe", "time", "type", "pet")}
    glob: dict[str, list] = {k: [] for k in ("ego", "time", "br", "sgap", "tgap")}
    for _, el in iterparse(str(path), tag=("conflict", "globalMeasures")):
        if el.tag == "conflict":
            ego, foe = el.get("ego"), el.get("foe")
            t = _floats(el.find("timeSpan").get("values")) if el.find("timeSpan") is not None \
                else np.zeros(0)
            n = len(t)
            spans = {}
            for key, tag in (("type", "typeSpan"), ("ttc", "TTCSpan"), ("drac", "DRACSpan"),
                             ("mdrac", "MDRACSpan"), ("ppet", "PPETSpan")):
                e = el.find(tag)
                v = _floats(e.get("values")) if e is not None else np.full(n, np.nan)
                spans[key] = v if len(v) == n else np.full(n, np.nan)
            lanes = {}
            for key, tag in (("ego_lane", "egoLane"), ("foe_lane", "foeLane")):
                e = el.find(tag)
                v = (e.get("values") or "").split() if e is not None else []
                lanes[key] = v if len(v) == n else [None] * n
            enc["ego"] += [ego] * n
            enc["foe"] += [foe] * n
            enc["time"].append(t)
            for k in ("type", "ttc", "drac", "mdrac", "ppet"):
                enc[k].append(spans[k])
            enc["ego_lane"] += lanes["ego_lane"]
            enc["foe_lane"] += lanes["foe_lane"]
            p = el.find("PET")
            if p is not None and p.get("value") not in (None, "NA"):
                pet["ego"].append(ego)
                pet["foe"].append(foe)
                pet["time"].append(float(p.get("time")))
                pet["type"].append(int(float(p.get("type"))))
                pet["pet"].append(float(p.get("value")))
        else:
            t = _floats(el.find("timeSpan").get("values"))
            n = len(t)
            glob["ego"] += [el.get("ego")] * n
            glob["time"].append(t)
            for key, tag in (("br", "BRSpan"), ("sgap", "SGAPSpan"), ("tgap", "TGAPSpan")):
                e = el.find(tag)
                v = _floats(e.get("values")) if e is not None else np.full(n, np.nan)
                glob[key].append(v if len(v) == n else np.full(n, np.nan))
        el.clear()

    def cat(d: dict[str, list], arrays: tuple[str, ...]) -> pa.Table:
        out = {}
        for k, v in d.items():
            if k in arrays:
                out[k] = pa.array(np.concatenate(v) if v else np.zeros(0), pa.float64())
            else:
                out[k] = pa.array(v, pa.string() if k not in ("time", "type", "pet") else None)
        return pa.table(out)

    e = cat(enc, ("time", "type", "ttc", "drac", "mdrac", "ppet"))
    e = e.set_column(e.schema.get_field_index("type"), "type",
                     pa.array(np.nan_to_num(e.column("type").to_numpy()).astype(np.int64)))
    return {"encounters": e, "pet": pa.table(pet) if pet["ego"] else pa.table(
        {k: pa.array([], t) for k, t in (("ego", pa.string()), ("foe", pa.string()),
                                          ("time", pa.float64()), ("type", pa.int64()),
                                          ("pet", pa.float64()))}),
            "globals": cat(glob, ("time", "br", "sgap", "tgap"))}


@dataclass
class SsmRun:
    """A SUMO run with the SSM device: the converted recording, the device's tables, the
    vehicles' minGap (SGAP subtracts it) and the working directory (None once removed)."""

    recording: Any
    ssm: dict[str, pa.Table]
    min_gap: dict[str, float]
    workdir: Path | None


@contextmanager
def _workdir(workdir: str | Path | None) -> Iterator[tuple[Path, bool]]:
    """``(directory, kept)``: ``workdir`` (created), or a temporary directory removed after."""
    if workdir is not None:
        wd = Path(workdir)
        wd.mkdir(parents=True, exist_ok=True)
        yield wd, True
        return
    tmp = tempfile.mkdtemp(prefix="aveas-ssm-")
    try:
        yield Path(tmp), False
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


_JUNCTION_NODES = """<nodes>
  <node id="C" x="0" y="0" type="priority"/>
  <node id="W" x="-{a}" y="0"/><node id="E" x="{a}" y="0"/>
  <node id="S" x="0" y="-{a}"/><node id="N" x="0" y="{a}"/>
</nodes>
"""


def _junction_edges(lanes: int, speed: float) -> str:
    rows = []
    for a, b, prio in (("W", "C", 2), ("C", "E", 2), ("E", "C", 2), ("C", "W", 2),
                       ("S", "C", 1), ("C", "N", 1), ("N", "C", 1), ("C", "S", 1)):
        rows.append(f'  <edge id="{a}{b}" from="{a}" to="{b}" numLanes="{lanes}" '
                    f'speed="{speed:g}" priority="{prio}"/>')
    return "<edges>\n" + "\n".join(rows) + "\n</edges>\n"


def _add_geo_reference(path: Path, proj: str) -> None:
    """Give the OpenDRIVE map netconvert wrote a ``<geoReference>`` (a recording needs a CRS)."""
    from lxml import etree

    from aveas_format.safeio import xml_parser

    tree = etree.parse(str(path), xml_parser())
    header = tree.getroot().find("header")
    if header is not None and header.find("geoReference") is None:
        g = etree.SubElement(header, "geoReference")
        g.text = etree.CDATA(proj)
        header.insert(0, g)
        tree.write(str(path), xml_declaration=True, encoding="UTF-8")


def junction_scenario(workdir: str | Path | None = None, *, duration: float = 120.0,
                      step: float = 0.1, seed: int = 1, flow_per_route: float = 150.0,
                      arm_m: float = 200.0, speed: float = 13.9, sigma: float = 0.5,
                      timeout: float = 300.0,
                      geo_reference: str = "+proj=tmerc +lat_0=52.5 +lon_0=13.3 +k=1 +x_0=0 "
                      "+y_0=0 +ellps=WGS84 +units=m +no_defs") -> SsmRun:
    """A 4-way priority junction (east-west road has priority), every route (straight, left,
    right from each arm) with ``flow_per_route`` veh/h, simulated for ``duration`` s at ``step``
    with the SSM device (drivers' imperfection ``sigma``, Krauss); the FCD becomes a recording on the OpenDRIVE map netconvert exports from
    the SUMO network. ``workdir`` keeps the files."""
    from aveas_format.converters import convert

    with _workdir(workdir) as (wd, keep):
        (wd / "n.nod.xml").write_text(_JUNCTION_NODES.format(a=f"{arm_m:g}"))
        (wd / "n.edg.xml").write_text(_junction_edges(1, speed))
        nc = str(find_sumo("netconvert"))
        log = wd / "netconvert.log"
        run_tool([nc, "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "net.net.xml", "--no-turnarounds",
              "--offset.disable-normalization", "true", "--no-warnings"], wd, log, "netconvert",
             timeout)
        run_tool([nc, "-s", "net.net.xml", "--opendrive-output", "map.xodr", "--no-warnings"], wd,
             log, "netconvert", timeout)
        _add_geo_reference(wd / "map.xodr", geo_reference)
        routes = ['<routes>', '  <vType id="car" vClass="passenger" length="5" width="1.8" '
                  f'minGap="2.5" sigma="{sigma:g}"/>']
        arms = {"W": ("WC", "CW"), "E": ("EC", "CE"), "S": ("SC", "CS"), "N": ("NC", "CN")}
        for a, (into, _) in arms.items():
            for b, (_, out) in arms.items():
                if a != b:
                    routes.append(f'  <flow id="{a}{b}" type="car" begin="0" end="{duration:g}" '
                                  f'probability="{flow_per_route / 3600.0:.6f}" '
                                  f'from="{into}" to="{out}" departSpeed="max" '
                                  'departLane="best"/>')
        routes.append("</routes>")
        (wd / "routes.rou.xml").write_text("\n".join(routes) + "\n")
        run_tool([str(find_sumo("sumo")), "-n", "net.net.xml", "-r", "routes.rou.xml",
              "--step-length", f"{step:g}", "--seed", str(seed), "--end", f"{duration:g}",
              "--fcd-output", "fcd.xml", "--fcd-output.attributes", "id,type,speed,lane,pos,x,y,"
              "angle,acceleration", "--no-step-log", "true", "--collision.action", "warn",
              *ssm_args("ssm.xml")], wd, wd / "sumo.log", "sumo", timeout)
        rec = convert("sumo-fcd", [wd / "fcd.xml"], map_source=wd / "map.xodr",
                      options={"net_file": str(wd / "net.net.xml"),
                               "vtypes": [str(wd / "routes.rou.xml")],
                               "partner": "aveas-format sim", "title": "SUMO junction with SSM"})
        rec = with_fcd_acceleration(rec, wd / "fcd.xml")
        return SsmRun(rec, read_ssm(wd / "ssm.xml"), {"car": 2.5}, wd if keep else None)


def with_fcd_acceleration(rec, fcd: str | Path):
    """``rec`` with the states' ``ax``/``ay`` from the FCD's ``acceleration`` (SUMO's
    longitudinal acceleration of the last step, along the heading): the crossing measures
    extrapolate braking with it, as SUMO's device does with the same value (a smoothed
    acceleration from derived/kinematics differs from it by the smoother's lag)."""
    from aveas_format.safeio import iterparse

    ids = _ids(rec)
    keys, acc = [], []
    t = 0.0
    for _, el in iterparse(str(fcd), tag=("timestep", "vehicle")):
        if el.tag == "timestep":
            t = float(el.get("time"))
            el.clear()
            continue
        a = el.get("acceleration")
        if a is not None and el.get("id") in ids:
            keys.append((ids[el.get("id")], round(t, 6)))
            acc.append(float(a))
    if not keys:
        return rec
    lookup = dict(zip(keys, acc))
    st = rec.states
    pid = st.column("participant_id").to_pylist()
    tt = np.round(st.column("time").to_numpy(), 6).tolist()
    a = np.array([lookup.get(k, np.nan) for k in zip(pid, tt)], float)
    h = st.column("heading").to_numpy(zero_copy_only=False).astype(float)
    for name, v in (("ax", a * np.cos(h)), ("ay", a * np.sin(h))):
        arr = pa.array(v, pa.float64(), mask=~np.isfinite(v))
        st = st.set_column(st.schema.get_field_index(name), name, arr) if name in \
            st.column_names else st.append_column(name, arr)
    rec.states = st
    return rec


def autobahn_scenario(workdir: str | Path | None = None, *, duration: float = 120.0,
                      step: float = 0.5, seed: int = 42, length: float = 1500.0,
                      inflow: float = 300.0, timeout: float = 600.0) -> SsmRun:
    """The paper's autobahn (:class:`~aveas_format.sim.Scenario` defaults: 3 lanes, cars and
    trucks, W99) on a shorter stretch, with the SSM device."""
    from aveas_format.sim.runner import simulate
    from aveas_format.sim.scenario import Network, Scenario

    with _workdir(workdir) as (wd, keep):
        sc = Scenario(network=Network(length=length, inflow=inflow), duration=duration,
                      step_length=step, seed=seed, drain=False, extra_args=ssm_args("ssm.xml"))
        res = simulate(sc, recording=True, workdir=wd, timeout=timeout)
        if not (wd / "ssm.xml").exists():
            raise SimulationError("sumo wrote no SSM output", path=wd / "ssm.xml")
        gaps = {c.name: c.w99()["cc0"] for c in sc.classes}
        return SsmRun(res.recording, read_ssm(wd / "ssm.xml"), gaps, wd if keep else None)


def _ids(rec) -> dict[str, int]:
    p = rec.participants
    return dict(zip(p.column("source_id").to_pylist(), p.column("participant_id").to_pylist()))


#: half a unit of the last decimal SUMO writes (``--precision 6``): a value of 3e-6 (a DRAC at a
#: closing speed of millimetres per second) is known to ±17 % only
OUTPUT_RESOLUTION = 0.5e-6


#: TTCs up to this (s) are resolved by the 6-decimal speeds (closing speeds >= ~2.5e-3 m/s at
#: the junction's gaps)
TTC_RESOLVED_S = 1000.0


def _share_within(a: np.ndarray, b: np.ndarray, rel: float) -> tuple[float, int]:
    """The share of samples (both finite, SUMO's positive) within ``rel`` of SUMO's value or
    within its output's rounding, and their number."""
    ok = np.isfinite(a) & np.isfinite(b) & (b > 0)
    if not ok.any():
        return float("nan"), 0
    tol = np.maximum(rel * np.abs(b[ok]), OUTPUT_RESOLUTION)
    return float(np.mean(np.abs(a[ok] - b[ok]) <= tol)), int(ok.sum())


def follower_pairs(run: SsmRun, time_decimals: int = 3) -> pa.Table:
    """SUMO's lane-follower samples (type 2, ego follows foe) matched with our ``leader`` rows of
    the same ego, foe and time: columns ego, foe, time, same_lane (SUMO's ego and foe lanes are
    the same), ttc/drac/mdrac of SUMO and ours (``ttc_ours`` ...), and ours' ``ttc_ca``."""
    import pyarrow.compute as pc

    rec = run.recording
    ids = _ids(rec)
    e = run.ssm["encounters"]
    e = e.filter(pc.equal(e.column("type"), FOLLOWING_FOLLOWER))
    it = rec.derived["interactions"]
    it = it.filter(pc.equal(it.column("relation"), "leader"))
    key = {(p, o, round(t, time_decimals)): k for k, (p, o, t) in enumerate(zip(
        *(it.column(c).to_pylist() for c in ("participant_id", "other_id", "time"))))}
    cols = {c: it.column(c).to_numpy(zero_copy_only=False).astype(float)
            if c in it.column_names else None for c in ("ttc", "drac", "mdrac", "ttc_ca", "gap")}
    rows: dict[str, list] = {k: [] for k in ("ego", "foe", "time", "same_lane", "ttc", "drac",
                                             "mdrac", "ttc_ours", "drac_ours", "mdrac_ours",
                                             "ttc_ca_ours", "gap_ours")}
    E = e.to_pydict()
    for ego, foe, t, ttc, drac, mdrac, el, fl in zip(E["ego"], E["foe"], E["time"], E["ttc"],
                                                     E["drac"], E["mdrac"], E["ego_lane"],
                                                     E["foe_lane"]):
        k = key.get((ids.get(ego), ids.get(foe), round(t, time_decimals)))
        if k is None:
            continue
        rows["ego"].append(ego)
        rows["foe"].append(foe)
        rows["time"].append(t)
        rows["same_lane"].append(el is not None and el == fl)
        rows["ttc"].append(ttc)
        rows["drac"].append(drac)
        rows["mdrac"].append(mdrac)
        for c in ("ttc", "drac", "mdrac", "ttc_ca", "gap"):
            rows[f"{c}_ours"].append(cols[c][k] if cols[c] is not None else np.nan)
    return pa.table(rows)


def _agreement(a: np.ndarray, b: np.ndarray, rel: float) -> dict[str, Any]:
    """Samples where both are finite, the share within ``rel`` of SUMO's ``b`` and the median
    relative difference."""
    share, n = _share_within(a, b, rel)
    with np.errstate(invalid="ignore", divide="ignore"):
        r = np.abs(a - b) / np.abs(b)
    r = r[np.isfinite(r)]
    return {"both_finite": n, "within": share,
            "median_rel": float(np.median(r)) if len(r) else None}


def _lookup(table: pa.Table, keys: tuple[str, ...], values: tuple[str, ...],
            time_decimals: int) -> dict[tuple, tuple]:
    """``{(key..., rounded time): (value, ...)}`` of a table's rows (the first row per key)."""
    cols = [table.column(k).to_pylist() for k in keys]
    t = np.round(table.column("time").to_numpy(zero_copy_only=False).astype(float),
                 time_decimals).tolist()
    vals = [table.column(v).to_numpy(zero_copy_only=False).astype(float) for v in values]
    out: dict[tuple, tuple] = {}
    for r, key in enumerate(zip(*cols, t)):
        out.setdefault(key, tuple(v[r] for v in vals))
    return out


def _matched(sumo: pa.Table, keys: tuple[str, ...], ours: dict[tuple, tuple],
             time_decimals: int) -> tuple[np.ndarray, int]:
    """For each row of SUMO's table the values of ours at the same keys and time (NaN rows where
    there is none) and the number matched."""
    cols = [sumo.column(k).to_pylist() for k in keys]
    t = np.round(sumo.column("time").to_numpy(zero_copy_only=False).astype(float),
                 time_decimals).tolist()
    width = len(next(iter(ours.values()))) if ours else 1
    nan = (np.nan,) * width
    got = [ours.get(key, None) for key in zip(*cols, t)]
    return np.array([g if g is not None else nan for g in got], float).reshape(-1, width), \
        sum(g is not None for g in got)


def _lanes_at(rec, time_decimals: int) -> dict[tuple, tuple]:
    """``{(participant, rounded time): (road, lane)}`` of the states on a lane outside junctions
    (the roads of the map's junctions, i.e. SUMO's internal lanes, are left out)."""
    st = rec.states
    if not {"road_id", "lane_id"} <= set(st.column_names):
        return {}
    junction = {rid for rid, r in rec.map.roads.items() if r.junction is not None}
    t = np.round(st.column("time").to_numpy(zero_copy_only=False).astype(float),
                 time_decimals).tolist()
    return {(p, tt): (r, ln) for p, tt, r, ln in zip(st.column("participant_id").to_pylist(), t,
                                                     st.column("road_id").to_pylist(),
                                                     st.column("lane_id").to_pylist())
            if r is not None and ln is not None and r not in junction}


def _globals_vs_leader(run: SsmRun, rel: float, time_decimals: int = 3) -> dict[str, Any]:
    """SUMO's SGAP and TGAP (global measures per vehicle and step) against ``gap`` and ``thw``
    of our ``leader`` rows of the same vehicle and time: overall and where the vehicle and our
    leader are on one lane outside the junction (``one_lane_*``; TGAP also for TGAPs up to
    :data:`TTC_RESOLVED_S`, which the FCD's 6-decimal speeds resolve)."""
    import pyarrow.compute as pc

    rec = run.recording
    src = {v: k for k, v in _ids(rec).items()}
    it = rec.derived["interactions"]
    it = it.filter(pc.equal(it.column("relation"), "leader"))
    lanes = _lanes_at(rec, time_decimals)
    t = np.round(it.column("time").to_numpy(zero_copy_only=False).astype(float),
                 time_decimals).tolist()
    one = [float(lanes.get((p, tt)) is not None and lanes.get((p, tt)) == lanes.get((o, tt)))
           for p, o, tt in zip(it.column("participant_id").to_pylist(),
                               it.column("other_id").to_pylist(), t)]
    it = it.append_column("ego", pa.array([src.get(i) for i in
                                           it.column("participant_id").to_pylist()], pa.string()))
    it = it.append_column("one_lane", pa.array(one, pa.float64()))
    ours, _ = _matched(run.ssm["globals"], ("ego",),
                       _lookup(it, ("ego",), ("gap", "thw", "one_lane"), time_decimals),
                       time_decimals)
    g = run.ssm["globals"]
    sgap, tgap = g.column("sgap").to_numpy(), g.column("tgap").to_numpy()
    on = ours[:, 2] == 1.0
    out = {"sgap": _agreement(ours[:, 0], sgap, rel), "tgap": _agreement(ours[:, 1], tgap, rel)}
    for m, k, b in (("sgap", 0, sgap), ("tgap", 1, tgap)):
        share, n = _share_within(ours[on, k], b[on], rel)
        out[m].update(one_lane_both_finite=n, one_lane_within=share)
    low = on & (tgap <= TTC_RESOLVED_S)
    out["tgap"]["one_lane_resolved_within"] = _share_within(ours[low, 1], tgap[low], rel)[0]
    return out


#: the junction's straight-on routes (crossing at right angles) and the pairs of left turns from
#: opposite arms, whose SUMO lanes pass each other without crossing (SUMO warns "Crossing point
#: between traffic from links ... not found" and logs them with a conflict distance of 0)
STRAIGHT_ROUTES = frozenset({"WE", "EW", "SN", "NS"})
OPPOSING_LEFT_TURNS = frozenset({frozenset({"WN", "ES"}), frozenset({"NE", "SW"})})


def _route(vehicle: str) -> str:
    return vehicle.split(".")[0]


def _crossings(run: SsmRun, rel: float, time_decimals: int = 3) -> dict[str, Any]:
    """SUMO's crossing encounters (types 10/11) against ``derived/conflicts`` of the same ego,
    foe and time (ttc, drac, ppet), overall and for straight-on pairs (``straight_*``, the
    junction's routes WE, EW, SN, NS: a right-angle crossing) and the others (``turning_*``);
    the pairs SUMO logs and those we find (``pairs``); SUMO's PETs against the conflicts'
    observed ``pet``, straight-on pairs and the others apart."""
    import pyarrow.compute as pc

    rec = run.recording
    src = {v: k for k, v in _ids(rec).items()}
    c = rec.derived["conflicts"]
    for name, col_ in (("ego", "participant_id"), ("foe", "other_id")):
        c = c.append_column(name, pa.array([src.get(i) for i in c.column(col_).to_pylist()],
                                           pa.string()))
    e = run.ssm["encounters"]
    e = e.filter(pc.is_in(e.column("type"), pa.array(list(CROSSING), pa.int64())))
    rows = _lookup(c, ("ego", "foe"), ("ttc", "drac", "ppet"), time_decimals)
    ours, n = _matched(e, ("ego", "foe"), rows, time_decimals)
    out: dict[str, Any] = {"sumo_samples": e.num_rows, "matched": n}
    egos, foes = e.column("ego").to_pylist(), e.column("foe").to_pylist()
    straight = np.array([_route(a) in STRAIGHT_ROUTES and _route(b) in STRAIGHT_ROUTES
                         for a, b in zip(egos, foes)], bool)
    for k, m in (("ttc", 0), ("drac", 1), ("ppet", 2)):
        sumo = e.column(k).to_numpy()
        out[k] = _agreement(ours[:, m], sumo, rel)
        out[f"straight_{k}"] = _agreement(ours[straight, m], sumo[straight], rel)
        out[f"turning_{k}"] = _agreement(ours[~straight, m], sumo[~straight], rel)
    # the pairs: a crossing is found where both recorded paths reach it; a vehicle still queued
    # when the run ends never does (SUMO knows its route)
    st = rec.states
    pid = st.column("participant_id").to_numpy()
    t = st.column("time").to_numpy()
    order = np.lexsort((t, pid))
    ends = np.r_[np.flatnonzero(np.diff(pid[order])), len(order) - 1]
    last = dict(zip(pid[order][ends].tolist(), t[order][ends].tolist()))
    t_end = float(t.max()) if len(t) else 0.0
    ids = _ids(rec)
    found = set(zip(c.column("ego").to_pylist(), c.column("foe").to_pylist()))
    sumo_pairs = set(zip(egos, foes))
    left = {p for p in sumo_pairs if all(last.get(ids.get(v), t_end) < t_end for v in p)}
    opposing = {p for p in sumo_pairs if frozenset(map(_route, p)) in OPPOSING_LEFT_TURNS}
    in_found = np.array([p in found for p in zip(egos, foes)], bool)
    out["pairs"] = {"sumo": len(sumo_pairs), "found": len(sumo_pairs & found),
                    "both_left_before_the_end": len(left),
                    "opposing_left_turns": len(opposing),
                    "missed": sorted(f"{a}/{b}" for a, b in (left - opposing - found)),
                    # SUMO's samples of the pairs found, and how many of them have a row here
                    "found_samples": int(in_found.sum()),
                    "found_samples_matched": int(sum(k in rows for k, f in zip(
                        zip(egos, foes, np.round(e.column("time").to_numpy(), time_decimals)
                            .tolist()), in_found) if f))}
    pet_ours: dict[tuple, float] = {}
    for ego, foe, v in zip(*(c.column(k).to_pylist() for k in ("ego", "foe", "pet"))):
        pet_ours.setdefault((ego, foe), np.nan if v is None else v)
    P = run.ssm["pet"].to_pydict()
    diffs: dict[str, list] = {"pet_straight": [], "pet_turning": []}
    for ego, foe, v in zip(P["ego"], P["foe"], P["pet"]):
        key = ("pet_straight" if _route(ego) in STRAIGHT_ROUTES and _route(foe) in
               STRAIGHT_ROUTES else "pet_turning")
        diffs[key].append(abs(v - pet_ours.get((ego, foe), np.nan)))
    for k, d in diffs.items():
        d = np.asarray(d, float)
        fin = d[np.isfinite(d)]
        out[k] = {"sumo": len(d), "matched": len(fin),
                  "max_abs_s": float(fin.max()) if len(fin) else None}
    return out


def compare(run: SsmRun, rel: float = 0.01) -> dict[str, Any]:
    """Agreement of the measures computed both ways: per measure the number of samples where both
    are finite and the share within ``rel`` (relative), overall and on one lane (SUMO's ego and
    foe on the same lane, i.e. not across a lane boundary or a junction's internal lanes);
    ``sgap``/``tgap`` against our leader rows' gap and thw; ``crossing`` (where the recording has
    ``derived/conflicts``): crossing TTC, DRAC, PPET and the PETs (docs/derive.md)."""
    fp = follower_pairs(run)
    out: dict[str, Any] = {"follower_samples": fp.num_rows}
    same = np.asarray(fp.column("same_lane").to_pylist(), bool)
    for m in ("ttc", "drac", "mdrac"):
        a = fp.column(f"{m}_ours").to_numpy(zero_copy_only=False).astype(float)
        b = fp.column(m).to_numpy(zero_copy_only=False).astype(float)
        share, n = _share_within(a, b, rel)
        s1, n1 = _share_within(a[same], b[same], rel)
        with np.errstate(invalid="ignore", divide="ignore"):
            r = np.abs(a - b) / np.abs(b)
        r = r[np.isfinite(r) & same]
        out[m] = {"both_finite": n, "within": share, "same_lane_both_finite": n1,
                  "same_lane_within": s1,
                  "same_lane_max_rel": float(r.max()) if len(r) else None,
                  "same_lane_median_rel": float(np.median(r)) if len(r) else None}
        if m == "ttc":
            # a TTC of 10^4 s and more is a closing speed of 10^-3 m/s and less, which the FCD's
            # 6 decimals (our input) round by 0.1 % and more
            low = same & (b <= TTC_RESOLVED_S)
            out[m]["same_lane_below_resolved_within"] = _share_within(a[low], b[low], rel)[0]
    out.update(_globals_vs_leader(run, rel))
    if "conflicts" in run.recording.derived:
        out["crossing"] = _crossings(run, rel)
    return out


#: SUMO's encounter types of a crossing: approaching (10, 11: ego leads / follows), in the
#: conflict area (12-14), leaving it (15-17)
CROSSING_PHASES = (10, 11, 12, 13, 14, 15, 16, 17)


def _episodes(pair: list, t: np.ndarray, gap: float) -> list[tuple[Any, float, float, np.ndarray]]:
    """``(pair, start, end, rows)`` of consecutive rows of one pair (rows sorted by pair, time;
    a new episode after a gap longer than ``gap``)."""
    out = []
    k = 0
    n = len(t)
    while k < n:
        j = k
        while j + 1 < n and pair[j + 1] == pair[k] and t[j + 1] - t[j] <= gap:
            j += 1
        out.append((pair[k], float(t[k]), float(t[j]), np.arange(k, j + 1)))
        k = j + 1
    return out


def _min(v) -> float | None:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    return float(v.min()) if len(v) else None


def compare_episodes(run: SsmRun, ttc_s: float = 3.0, pet_s: float = 2.0, gap_s: float = 0.5,
                     slack_s: float = 1.0) -> dict[str, Any]:
    """SUMO's crossing conflicts against ``derived/conflicts``, conflict by conflict.

    A *conflict episode* is a pair's consecutive crossing samples (:data:`CROSSING_PHASES`;
    gaps up to ``gap_s``) with TTC <= ``ttc_s`` or PPET <= ``pet_s``, plus the pair's observed
    PET <= ``pet_s``; ours the same from ``derived/conflicts`` (``ttc``, ``ppet``, ``pet``). A
    SUMO episode is matched by an episode of ours of the same pair overlapping it in time (within
    ``slack_s``). SUMO's episodes are classified by where the definitions differ (docs/derive.md):
    ``opposing_left_turns`` (SUMO's lanes pass each other without crossing: it logs them with a
    conflict distance of 0, values that are not measurements), ``not_in_recording`` (a vehicle
    still on its way when the run ends: SUMO knows its route, the recording not its path); the
    rest are ``comparable``. Per matched comparable episode the minimum TTC, minimum PPET and
    PET of both, and (``*_max_abs_s``) the largest difference of the minimum TTC and of the PET
    over the episodes of ``straight`` pairs (both on straight-on routes: a right-angle crossing,
    where the conflict areas are the same) and of the others."""
    import pyarrow.compute as pc

    rec = run.recording
    ids = _ids(rec)
    src = {v: k for k, v in ids.items()}
    e = run.ssm["encounters"]
    e = e.filter(pc.is_in(e.column("type"), pa.array(list(CROSSING_PHASES), pa.int64())))
    E = e.to_pandas()
    E = E[(E.ttc <= ttc_s) | (E.ppet <= pet_s)]
    E = E.assign(pair=[tuple(sorted(p)) for p in zip(E.ego, E.foe)]).sort_values(["pair", "time"])
    c = rec.derived["conflicts"].to_pandas()
    c = c.assign(pair=[tuple(sorted((src.get(a), src.get(b)))) for a, b in
                       zip(c.participant_id, c.other_id)])
    O = c[(c.ttc <= ttc_s) | (c.ppet <= pet_s) | (c.pet <= pet_s)].sort_values(["pair", "time"])
    P = run.ssm["pet"].to_pandas()
    P = P[P.pet.between(0.0, pet_s)]
    sumo_eps = [(p, a, b, E.iloc[r]) for p, a, b, r in _episodes(list(E.pair), E.time.to_numpy(),
                                                                  gap_s)]
    for _, row in P.iterrows():  # an observed PET below the threshold: an episode at its time
        p = tuple(sorted((row.ego, row.foe)))
        if not any(q == p and a - pet_s - slack_s <= row.time <= b + pet_s + slack_s
                   for q, a, b, _ in sumo_eps):
            sumo_eps.append((p, float(row.time) - float(row.pet), float(row.time), E.iloc[0:0]))
    ours = _episodes(list(O.pair), O.time.to_numpy(), gap_s)
    st = rec.states
    pid, t = st.column("participant_id").to_numpy(), st.column("time").to_numpy()
    t_end = float(t.max()) if len(t) else 0.0
    last = {}
    for i, tt in zip(pid.tolist(), t.tolist()):
        last[i] = max(last.get(i, -np.inf), tt)
    rows = []
    for p, a, b, S in sumo_eps:
        if frozenset(map(_route, p)) in OPPOSING_LEFT_TURNS:
            cls = "opposing_left_turns"
        elif any(last.get(ids.get(v), t_end) >= t_end for v in p):
            cls = "not_in_recording"
        else:
            cls = "comparable"
        mine = [r for q, x, y, r in ours if q == p and x <= b + slack_s + pet_s
                and y >= a - slack_s - pet_s]
        r = O.iloc[np.concatenate(mine)] if mine else O.iloc[0:0]
        pet_sumo = P[[tuple(sorted(q)) == p for q in zip(P.ego, P.foe)]].pet
        rows.append({"pair": "/".join(p), "start": a, "end": b, "class": cls,
                     "straight": all(_route(v) in STRAIGHT_ROUTES for v in p),
                     "matched": bool(mine),
                     "sumo_min_ttc": _min(S.ttc), "ours_min_ttc": _min(r.ttc),
                     "sumo_min_ppet": _min(S.ppet), "ours_min_ppet": _min(r.ppet),
                     "sumo_pet": float(pet_sumo.min()) if len(pet_sumo) else None,
                     "ours_pet": float(r.pet.min()) if len(r) and r.pet.notna().any() else None})
    comp = [r for r in rows if r["class"] == "comparable"]

    def diffs(key: str, straight: bool) -> list[float]:
        return [abs(r[f"ours_{key}"] - r[f"sumo_{key}"]) for r in comp if r["matched"]
                and r["straight"] == straight and r[f"ours_{key}"] is not None
                and r[f"sumo_{key}"] is not None]

    out: dict[str, Any] = {"sumo_episodes": len(rows),
                           "by_class": {k: sum(r["class"] == k for r in rows) for k in
                                        ("comparable", "not_in_recording",
                                         "opposing_left_turns")},
                           "comparable_matched": sum(r["matched"] for r in comp),
                           "ours_episodes": len(ours), "episodes": rows}
    for key in ("min_ttc", "pet"):
        for straight in (True, False):
            d = diffs(key, straight)
            out[f"{'straight' if straight else 'turning'}_{key}_max_abs_s"] = (
                max(d) if d else None)
            out[f"{'straight' if straight else 'turning'}_{key}_n"] = len(d)
    return out


__all__ = ["CROSSING", "CROSSING_PHASES", "FOLLOWING_FOLLOWER", "MERGING", "SSM_MEASURES",
           "SsmRun", "autobahn_scenario", "compare", "compare_episodes", "follower_pairs",
           "junction_scenario", "read_ssm", "ssm_args", "with_fcd_acceleration"]
