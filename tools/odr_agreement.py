"""World -> road agreement of the OpenDRIVE engine with CARLA's (``carla.Map(name, xodr_text)``,
offline, PyPI wheel ``carla``): docs/opendrive.md quotes what this prints.

CARLA needs its own interpreter (its wheel pins its own stack), so the measurement runs in two
steps that exchange one ``.npz`` per map::

    .venv/bin/python tools/odr_agreement.py sample OUT_DIR MAP.xodr...     # points + our (s, t)
    CARLA_PY tools/odr_agreement.py carla OUT_DIR                         # CARLA's waypoints
    .venv/bin/python tools/odr_agreement.py report OUT_DIR                # the table below

Points are drawn inside drivable lanes (``RoadNetwork.sample_lane_points``); a point counts when
both engines put it on the same road and lane (junction overlaps may choose differently). CARLA's
frame has y flipped (left-handed): its location is (x, -y). Columns: ``max|ds|`` between our s of
the sampled point and the s of CARLA's waypoint (CARLA's foot-point search is coarse: it snaps to
its own waypoint sampling, so this is a loose bound); ``max centre gap``: our lane centre at
CARLA's (road, lane, s) against CARLA's waypoint location (the geometry, paramPoly3 included);
``max|ds| wp``: CARLA's waypoint location projected by us, our s against CARLA's s (the
parameterisation along the road).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

N = 2000


def sample(out: Path, maps: list[str]) -> None:
    from aveas_format.opendrive import load_map

    out.mkdir(parents=True, exist_ok=True)
    for m in maps:
        net = load_map(m)
        pts = net.sample_lane_points(N, seed=1)
        x, y, _, _ = net.road_to_world(pts["road_id"], pts["s"], pts["t"])
        pr = net.world_to_road(x, y)
        np.savez(out / (Path(m).stem + ".npz"), xodr=Path(m).read_text(), x=x, y=y,
                 road=pr.road_id.astype(str), lane=pr.lane_id, s=pr.s, t=pr.t)


def carla_side(out: Path) -> None:
    import carla

    for f in sorted(out.glob("*.npz")):
        d = dict(np.load(f, allow_pickle=True))
        try:
            cm = carla.Map(f.stem, str(d["xodr"]))
        except Exception as e:  # noqa: BLE001 - CARLA's parser rejects some maps
            print(f"{f.stem}: CARLA cannot read it: {type(e).__name__}: {e}")
            continue
        road, lane, s, cx, cy = [], [], [], [], []
        for x, y in zip(d["x"], d["y"]):
            wp = cm.get_waypoint(carla.Location(x=float(x), y=-float(y), z=0.0), project_to_road=True)
            road.append(str(wp.road_id))
            lane.append(wp.lane_id)
            s.append(wp.s)
            cx.append(wp.transform.location.x)
            cy.append(-wp.transform.location.y)
        d.update(c_road=np.array(road), c_lane=np.array(lane), c_s=np.array(s), c_x=np.array(cx),
                 c_y=np.array(cy))
        np.savez(f, **d)


def report(out: Path) -> None:
    from aveas_format.opendrive import load_map

    print(f"{'map':32s} {'points':>7s} {'same lane':>9s} {'max|ds| m':>10s} {'p99|ds| m':>10s} "
          f"{'max centre gap m':>16s} {'max|ds| wp m':>14s}")
    for f in sorted(out.glob("*.npz")):
        d = dict(np.load(f, allow_pickle=True))
        if "c_s" not in d:
            continue
        net = load_map(str(d["xodr"]))
        same = (d["road"] == d["c_road"]) & (d["lane"] == d["c_lane"])
        ds = np.abs(d["s"][same] - d["c_s"][same])
        # CARLA's lane centre at its s, against ours at the same (road, lane, s)
        inner, outer = net.lane_borders(d["road"][same], d["c_s"][same], d["lane"][same])
        x, y, _, _ = net.road_to_world(d["road"][same], d["c_s"][same], 0.5 * (inner + outer))
        gap = np.hypot(x - d["c_x"][same], y - d["c_y"][same])
        # CARLA's waypoint (on its lane centre at its s) projected by us: the s of the same point
        pr = net.world_to_road(d["c_x"][same], d["c_y"][same])
        ok = pr.road_id.astype(str) == d["road"][same]
        dsw = np.abs(pr.s[ok] - d["c_s"][same][ok])
        print(f"{f.stem:32s} {len(same):7d} {same.mean():9.1%} {ds.max():10.4f} "
              f"{np.quantile(ds, 0.99):10.4f} {np.nanmax(gap):16.4f} {dsw.max():14.5f}")


if __name__ == "__main__":
    cmd, out = sys.argv[1], Path(sys.argv[2])
    {"sample": lambda: sample(out, sys.argv[3:]), "carla": lambda: carla_side(out),
     "report": lambda: report(out)}[cmd]()
