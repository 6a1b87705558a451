"""A map built from an hour of a busy highway (issue 43): ~9M states of a highD-like drone
recording (a straight motorway, three lanes each way, a third of the vehicles changing lanes;
``tests/helpers_mapbuild.highd_like``) -> OpenDRIVE with :func:`aveas_format.opendrive.roadfit.tracks.map_from_tracks`
(flow field, reference lines, lanes, fit report). Target: <= 60 s on 2 cores.

Baseline in the same run: referencing the same states against the built map
(``RoadNetwork.world_to_road`` of every state), the step every recording needs once it has a map.
Also reported: the share of states that the built map puts in the lane the source's lane ids
name (target >= 99 %).

Run alone: ``.venv/bin/python benchmarks/bench_map_build.py [N_VEHICLES]`` (default 26 000, ~9M states).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))


def bench_lanelet2() -> list[dict]:
    """Lanelet2's Karlsruhe example map (../shared) -> OpenDRIVE; baseline: loading the same map
    with Lanelet2 itself (PyPI lanelet2, its UtmProjector), in the same run."""
    osm = HERE.parent.parent / "shared" / "data" / "real" / "lanelet2" / "lanelet2__mapping_example.osm"
    if not osm.exists():
        return []
    from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive

    t0 = time.perf_counter()
    conv = lanelet2_to_opendrive(osm, origin=(49.0, 8.4))
    t = time.perf_counter() - t0
    base = None
    try:
        import lanelet2
        from lanelet2.io import Origin
        from lanelet2.projection import UtmProjector

        t0 = time.perf_counter()
        lanelet2.io.load(str(osm), UtmProjector(Origin(49.0, 8.4)))
        base = time.perf_counter() - t0
    except ImportError:
        pass
    return [{"benchmark": "lanelet2_to_opendrive_karlsruhe", "seconds": round(t, 2), "rows_per_s": conv.lanelets / t,
             "baseline_s": None if base is None else round(base, 3),
             "speedup_vs_baseline": None if base is None else round(base / t, 4),
             "note": f"{conv.lanelets} lanelets -> {conv.roads} roads, {conv.junctions} junctions (rows = lanelets); "
                     "baseline: lanelet2.io.load of the map (reading only)"}]


def main(n_vehicles: int = 26_000) -> list[dict]:
    from helpers_mapbuild import highd_like, lane_agreement

    from aveas_format.opendrive.roadfit.tracks import map_from_tracks

    t0 = time.perf_counter()
    d = highd_like(n_vehicles, duration=3600.0, seed=1)
    gen = time.perf_counter() - t0
    n = len(d["x"])
    t0 = time.perf_counter()
    built = map_from_tracks(d["x"], d["y"], d["track"], d["time"], heading=d["heading"])
    t_build = time.perf_counter() - t0
    net = built.network()
    t0 = time.perf_counter()
    net.world_to_road(d["x"], d["y"], d["heading"], drivable_only=True)
    t_ref = time.perf_counter() - t0
    sub = np.flatnonzero(np.isin(d["track"], np.arange(0, n_vehicles, 20)))  # every 20th track
    agree = lane_agreement(net, {k: v[sub] for k, v in d.items()})
    note = (f"{n:,} states ({gen:.1f} s to generate): {built.roads} roads, {built.lanes} lanes, "
            f"{100 * built.report['on_lane_share']:.2f} % on a lane, lateral p95 {built.report['lateral_p95_m']} m, "
            f"{100 * agree:.2f} % of states in the source's lane (every 20th track); baseline: world_to_road of "
            f"every state against the built map")
    return [{"benchmark": "map_build_highway_hour", "seconds": round(t_build, 2), "rows_per_s": n / t_build,
             "baseline_s": round(t_ref, 2), "speedup_vs_baseline": round(t_ref / t_build, 2), "note": note}
            ] + bench_lanelet2()


if __name__ == "__main__":
    from run import format_row

    for row in main(int(sys.argv[1]) if len(sys.argv) > 1 else 26_000):
        print(format_row(row))
