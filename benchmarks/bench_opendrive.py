"""Benchmark of the OpenDRIVE engine: load time per map, world -> road throughput.

Run ``python benchmarks/bench_opendrive.py`` (or ``make bench``). The maps are read from
``../shared/data/xodr/`` next to the repository (``--maps DIR`` to change). Throughput is measured
on random points inside lanes of Town04 and e6mini (``--points`` per run, best of ``--repeat``),
with all candidates resolved (road, lane, s, t, lane offset) as ``RoadNetwork.world_to_road`` does.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np

from aveas_format.opendrive import load_map

DEFAULT_MAPS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "xodr"
THROUGHPUT_MAPS = ("opendrive-test-files__Town04.xodr", "esmini__e6mini.xodr")


def _timed(fn, repeat: int) -> tuple[float, object]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_load(maps: list[Path], repeat: int) -> None:
    print(f"{'map':45s} {'roads':>6s} {'load [ms]':>10s} {'index [ms]':>11s}")
    for path in maps:
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            net = load_map(path)
            times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        net.spatial_index  # noqa: B018 - built on first use
        t_index = time.perf_counter() - t0
        print(f"{path.name:45s} {len(net.roads):6d} {1e3 * statistics.median(times):10.1f} {1e3 * t_index:11.1f}")


def bench_projection(path: Path, n: int, repeat: int, threads: int | None) -> None:
    net = load_map(path)
    net.spatial_index  # noqa: B018
    smp = net.sample_lane_points(n, seed=0)
    x, y, _, _ = net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    t_fwd, _ = _timed(lambda: net.road_to_world(smp["road_id"], smp["s"], smp["t"]), repeat)
    t, proj = _timed(lambda: net.world_to_road(x, y, threads=threads), repeat)
    ok = (proj.road_id == smp["road_id"]) | (proj.n_candidates > 1)
    multi = float(np.mean(proj.n_candidates > 1))
    print(
        f"{path.name:45s} world->road {n / t:12,.0f} points/s  ({n:,} points, {t:.3f} s, "
        f"{100 * multi:.1f} % on several roads, {100 * ok.mean():.2f} % consistent)   road->world {n / t_fwd:12,.0f} points/s"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=Path, default=DEFAULT_MAPS, help="folder of .xodr maps")
    ap.add_argument("--points", type=int, default=1_000_000, help="points per throughput run")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="worker threads (default: up to 4)")
    args, _ = ap.parse_known_args(argv)  # tolerate the flags of a calling runner (benchmarks/run.py)
    maps = sorted(args.maps.glob("*.xodr"))
    if not maps:
        raise SystemExit(f"no .xodr maps in {args.maps}")
    print(f"OpenDRIVE engine benchmark ({os.cpu_count()} CPUs)\n")
    bench_load(maps, args.repeat)
    print()
    for name in THROUGHPUT_MAPS:
        path = args.maps / name
        if path.exists():
            bench_projection(path, args.points, args.repeat, args.threads)


if __name__ == "__main__":
    main()
