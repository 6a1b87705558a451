"""A SUMO network with a lane drop and a four-way junction, simulated: the trajectories a map is
built from, and netconvert's own OpenDRIVE export of the network as the truth."""

from __future__ import annotations

import gzip
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

NODES = """<nodes>
  <node id="W" x="-300" y="0"/><node id="C" x="0" y="0" type="priority"/><node id="E" x="300" y="0"/>
  <node id="F" x="700" y="0"/><node id="N" x="0" y="250"/><node id="S" x="0" y="-250"/>
</nodes>"""
# eastbound three lanes C->E dropping to two at E; the arms of the junction C one or two lanes each way
EDGES = """<edges>
  <edge id="WC" from="W" to="C" numLanes="2" speed="13.9"/><edge id="CW" from="C" to="W" numLanes="2" speed="13.9"/>
  <edge id="CE" from="C" to="E" numLanes="3" speed="13.9"/><edge id="EC" from="E" to="C" numLanes="2" speed="13.9"/>
  <edge id="EF" from="E" to="F" numLanes="2" speed="13.9"/><edge id="FE" from="F" to="E" numLanes="2" speed="13.9"/>
  <edge id="NC" from="N" to="C" numLanes="1" speed="13.9"/><edge id="CN" from="C" to="N" numLanes="1" speed="13.9"/>
  <edge id="SC" from="S" to="C" numLanes="1" speed="13.9"/><edge id="CS" from="C" to="S" numLanes="1" speed="13.9"/>
</edges>"""
ROUTES = {  # every turning movement at C (no U-turns), the eastbound ones on through the lane drop
    "W_E": "WC CE EF", "W_N": "WC CN", "W_S": "WC CS", "N_S": "NC CS", "N_E": "NC CE EF", "N_W": "NC CW",
    "S_N": "SC CN", "S_W": "SC CW", "S_E": "SC CE EF", "F_W": "FE EC CW", "F_N": "FE EC CN", "F_S": "FE EC CS",
}


@dataclass
class Scene:
    truth: Path          # netconvert's OpenDRIVE of the network
    x: np.ndarray        # vehicle centres in the network frame
    y: np.ndarray
    heading: np.ndarray
    track: np.ndarray
    time: np.ndarray
    lane: np.ndarray     # SUMO lane id per point
    movements: set[tuple[str, str]]  # (from edge, to edge) driven through the junction C


def sumo_scene(folder: Path, duration: float = 900.0, per_hour: float = 150.0) -> Scene:
    from aveas_format.sim.runner import find_sumo

    try:
        netconvert, sumo = find_sumo("netconvert"), find_sumo("sumo")
    except Exception as e:  # noqa: BLE001 - any reason SUMO is not there
        pytest.skip(f"SUMO is not installed: {e}")
    (folder / "n.nod.xml").write_text(NODES)
    (folder / "n.edg.xml").write_text(EDGES)
    flows = "".join(f'<flow id="{k}" type="car" route="{k}" begin="0" end="{duration - 120}" '
                    f'vehsPerHour="{per_hour}" departLane="random" departSpeed="max"/>' for k in ROUTES)
    routes = "".join(f'<route id="{k}" edges="{v}"/>' for k, v in ROUTES.items())
    (folder / "r.rou.xml").write_text(f'<routes><vType id="car" length="4.5" width="1.8"/>{routes}{flows}</routes>')
    subprocess.run([str(netconvert), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "net.net.xml",
                    "--opendrive-output", "truth.xodr", "--no-turnarounds", "--no-warnings"],
                   cwd=folder, check=True, capture_output=True, timeout=300)
    subprocess.run([str(sumo), "-n", "net.net.xml", "-r", "r.rou.xml", "--fcd-output", "fcd.xml.gz",
                    "--step-length", "0.2", "--end", str(duration), "--seed", "5", "--no-warnings",
                    "--no-step-log"], cwd=folder, check=True, capture_output=True, timeout=600)
    rows = []
    with gzip.open(folder / "fcd.xml.gz") as f:
        for _, el in etree.iterparse(f, tag="timestep"):
            t = float(el.get("time"))
            for v in el.iterfind("vehicle"):
                rows.append((t, v.get("id"), float(v.get("x")), float(v.get("y")), float(v.get("angle")),
                             v.get("lane")))
            el.clear()
    t = np.array([r[0] for r in rows])
    vid = np.array([r[1] for r in rows])
    fx, fy = np.array([r[2] for r in rows]), np.array([r[3] for r in rows])
    heading = np.radians(90.0 - np.array([r[4] for r in rows]))
    lane = np.array([r[5] for r in rows])
    # SUMO writes the front bumper: the centre is half a length back
    x, y = fx - 2.25 * np.cos(heading), fy - 2.25 * np.sin(heading)
    movements = set()
    edge = np.array([ln.rsplit("_", 1)[0] for ln in lane])
    for v in np.unique(vid):
        e = [k for k in edge[vid == v] if not k.startswith(":")]
        seq = [k for i, k in enumerate(e) if i == 0 or k != e[i - 1]]
        for a, b in zip(seq[:-1], seq[1:]):
            if a.endswith("C") and b.startswith("C"):
                movements.add((a, b))
    shutil.rmtree(folder / "fcd.xml.gz", ignore_errors=True)
    return Scene(folder / "truth.xodr", x, y, heading, vid, t, lane, movements)


def lane_centres(net, step: float = 1.0, junctions: bool = False):
    """Points along every lane centre of ``net`` (outside junctions unless asked): x, y, heading of
    the road, road id, lane id."""
    xs, ys, hs, rids, lids = [], [], [], [], []
    for road in net.roads.values():
        if (road.junction is not None) != junctions and not junctions:
            continue
        for k, sec in enumerate(road.lane_sections):
            s1 = road.lane_sections[k + 1].s if k + 1 < len(road.lane_sections) else road.length
            s = np.arange(sec.s + step / 2, s1, step)
            for lane in sec.left + sec.right:
                inner, outer = net.lane_borders(road.id, s, np.full(len(s), lane.id))
                x, y, _, h = net.road_to_world(road.id, s, 0.5 * (inner + outer))
                xs.append(x), ys.append(y), hs.append(h)
                rids += [road.id] * len(s)
                lids += [lane.id] * len(s)
    return (np.concatenate(xs), np.concatenate(ys), np.concatenate(hs), np.array(rids, dtype=object),
            np.array(lids))


def driven(x, y, px, py, radius: float = 1.0) -> np.ndarray:
    """Which points (x, y) lie within ``radius`` m of a trajectory point (px, py)."""
    from scipy.spatial import cKDTree

    d, _ = cKDTree(np.column_stack([px, py])).query(np.column_stack([x, y]), distance_upper_bound=radius)
    return np.isfinite(d)


# --- a highD-like recording ---------------------------------------------------------------------------
#: lane centres (y, metres, y up) and highD's lane ids: the upper carriageway drives towards -x
#: (lanes 2, 3, 4 from the top), the lower towards +x (6, 7, 8 from the median down)
HIGHD_LANES = {2: 9.75, 3: 6.25, 4: 2.75, 6: -2.75, 7: -6.25, 8: -9.75}


def highd_like(n_vehicles: int, *, length: float = 420.0, duration: float = 3600.0, rate: float = 25.0,
               change_share: float = 0.3, noise: float = 0.05, seed: int = 0):
    """States of a highD-like drone recording (vectorised): a straight motorway, three lanes each
    way, vehicles entering at random times at their lane's speed, a share of them changing to a
    neighbouring lane over 4 s (smoothstep), positions with ``noise`` m of noise. Returns a dict
    of arrays: track, time, x, y, heading, lane (highD's lane id: the lane whose centre is
    nearest, as highD assigns it by the markings)."""
    rng = np.random.default_rng(seed)
    ids = np.array(list(HIGHD_LANES))
    lane0 = rng.choice(ids, n_vehicles)
    upper = lane0 <= 4
    speed = np.array([{2: 24, 3: 30, 4: 36, 6: 36, 7: 30, 8: 24}[k] for k in lane0]) * rng.normal(1, 0.05, n_vehicles)
    n_steps = np.ceil(length / speed * rate).astype(np.int64) + 1
    t0 = rng.uniform(0.0, duration - length / speed.min(), n_vehicles)
    veh = np.repeat(np.arange(n_vehicles), n_steps)
    k = np.arange(len(veh)) - np.repeat(np.cumsum(n_steps) - n_steps, n_steps)
    t = t0[veh] + k / rate
    along = speed[veh] * (k / rate)
    x = np.where(upper[veh], length - along, along)
    # lane changes: to the neighbouring lane (inwards or outwards), at a random point
    change = rng.random(n_vehicles) < change_share
    y0 = np.array([HIGHD_LANES[k] for k in lane0])
    step = np.where(rng.random(n_vehicles) < 0.5, 3.5, -3.5)
    y1 = y0 + step
    valid = np.isin(np.round(y1, 2), np.round(list(HIGHD_LANES.values()), 2)) & (np.sign(y1) == np.sign(y0))
    y1 = np.where(change & valid, y1, y0)
    tc = rng.uniform(0.2, 0.7, n_vehicles) * (length / speed)
    u = np.clip((k / rate - tc[veh]) / 4.0 + 0.5, 0.0, 1.0)
    y = y0[veh] + (y1 - y0)[veh] * u * u * (3 - 2 * u)
    heading = np.where(upper[veh], np.pi, 0.0)
    x = x + rng.normal(0, noise, len(x))
    y_noisy = y + rng.normal(0, noise, len(y))
    centres = np.array(list(HIGHD_LANES.values()))
    lane = ids[np.argmin(np.abs(y[:, None] - centres[None, :]), axis=1)]
    return {"track": veh, "time": t, "x": x, "y": y_noisy, "heading": heading, "lane": lane}


def lane_agreement(net, d) -> float:
    """The share of states whose lane in ``net`` (referenced along their tracks) is the one the
    source's lane id maps to: each built (road, lane) stands for the source lane most of its
    states have."""
    pr = net.world_to_road_track(d["x"], d["y"], d["heading"], d["time"], d["track"], drivable_only=True)
    key = np.array([f"{r}|{l}" for r, l in zip(pr.road_id, pr.lane_id)])
    uk, inv = np.unique(key, return_inverse=True)
    us, sinv = np.unique(d["lane"], return_inverse=True)
    counts = np.zeros((len(uk), len(us)), dtype=np.int64)
    np.add.at(counts, (inv, sinv), 1)
    best = counts.argmax(1)
    ok = (best[inv] == sinv) & (pr.n_candidates > 0)
    return float(ok.mean())


def lane_counts(built, truth, px, py, step: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """At points every ``step`` m along the built map's lane centres where traffic drove: the
    built road's lane count there and the truth's count of lanes of that direction that carry
    traffic there (a lane centre within 1 m of a trajectory point)."""
    from scipy.spatial import cKDTree

    x, y, h, rid, lid = lane_centres(built, step=step)
    m = driven(x, y, px, py)
    x, y, h, rid = x[m], y[m], h[m], rid[m]
    tree = cKDTree(np.column_stack([px, py]))
    ours, theirs = [], []
    pr = truth.world_to_road(x, y, h, drivable_only=True)
    for i in np.flatnonzero(pr.n_candidates > 0):
        road = built.roads[rid[i]]
        s_b, _ = built.world_to_road(x[i:i + 1], y[i:i + 1]).s, None
        sec = road.lane_sections[road.section_index(float(s_b[0]))]
        ours.append(len(sec.right) + len(sec.left))
        troad = truth.roads[pr.road_id[i]]
        tsec = troad.lane_sections[troad.section_index(float(pr.s[i]))]
        same_side = tsec.right if pr.lane_id[i] < 0 else tsec.left
        n = 0
        for lane in same_side:
            if lane.type != "driving":
                continue
            inner, outer = truth.lane_borders(troad.id, [pr.s[i]], [lane.id])
            cx, cy, _, _ = truth.road_to_world(troad.id, [pr.s[i]], [0.5 * (inner[0] + outer[0])])
            if np.isfinite(tree.query([cx[0], cy[0]], distance_upper_bound=1.0)[0]):
                n += 1
        theirs.append(n)
    return np.array(ours), np.array(theirs)
