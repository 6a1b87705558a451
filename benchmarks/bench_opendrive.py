"""Benchmark of the OpenDRIVE engine: load time per map, world -> road throughput, road fitting.

Run ``python benchmarks/bench_opendrive.py`` (or ``make bench``). The maps are read from
``../shared/data/xodr/`` next to the repository (``--maps DIR`` to change). Throughput is measured
on random points inside lanes of Town04 and e6mini (``--points`` per run, best of ``--repeat``),
with all candidates resolved (road, lane, s, t, lane offset) as ``RoadNetwork.world_to_road`` does.

Baseline, measured in the same run on the same points (the first ``--baseline-points`` of them: it
is slow; its time is scaled to all points for the ratio): the naive shapely approach (every road's
reference line sampled every 0.5 m as a LineString, ``STRtree.query_nearest`` for the nearest road,
``line_locate_point`` for s and ``distance`` for |t|). It gives one road per point, no lane, no sign
of t, and s/t only as exact as the sampling; the engine gives all of that exactly.

``main()`` prints a table and returns a list of row dicts (``benchmark``, ``rows``, ``seconds``,
``rows_per_s``, ``baseline_s``, ``speedup_vs_baseline``, ``note``) for ``benchmarks/run.py``.
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


def bench_load(maps: list[Path], repeat: int) -> list[dict]:
    rows = []
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
        t_load = statistics.median(times)
        print(f"{path.name:45s} {len(net.roads):6d} {1e3 * t_load:10.1f} {1e3 * t_index:11.1f}")
        rows.append(_row(f"opendrive.load.{_short(path)}", len(net.roads), t_load, None,
                         f"{len(net.roads)} roads (rows = roads); index {1e3 * t_index:.1f} ms"))
    return rows


def _short(path: Path) -> str:
    return path.stem.split("__")[-1]


def _row(name: str, n: int, t: float, base: float | None, note: str) -> dict:
    return {"benchmark": name, "rows": int(n), "seconds": round(t, 4), "rows_per_s": round(n / t) if t > 0 else None,
            "baseline_s": None if base is None else round(base, 4),
            "speedup_vs_baseline": None if base is None else round(base / t, 1), "note": note}


def shapely_baseline(net, x: np.ndarray, y: np.ndarray, step: float = 0.5):
    """Naive world -> road: nearest sampled reference line (STRtree) -> (road index, s, |t|).

    Returns the seconds of the query (the sampling and tree building, done once per map, are not
    counted) and the results."""
    import shapely

    lines, lengths = [], []
    for rid, road in net.roads.items():
        n = max(2, int(np.ceil(road.length / step)) + 1)
        s = np.linspace(0.0, road.length, n)
        rx, ry, _, _ = net.reference_line(rid, s)
        lines.append(shapely.linestrings(np.column_stack([rx, ry])))
        lengths.append(road.length)
    lines = np.array(lines, dtype=object)
    tree = shapely.STRtree(lines)
    t0 = time.perf_counter()
    pts = shapely.points(x, y)
    (ipt, iline), dist = tree.query_nearest(pts, return_distance=True, all_matches=False)
    s = shapely.line_locate_point(lines[iline], pts[ipt])
    elapsed = time.perf_counter() - t0
    road = np.full(len(x), -1)
    road[ipt] = iline
    s_out = np.full(len(x), np.nan)
    s_out[ipt] = s
    t_abs = np.full(len(x), np.nan)
    t_abs[ipt] = dist
    return elapsed, road, s_out, t_abs


def bench_projection(path: Path, n: int, repeat: int, threads: int | None, baseline_points: int = 50_000) -> list[dict]:
    net = load_map(path)
    net.spatial_index  # noqa: B018
    smp = net.sample_lane_points(n, seed=0)
    x, y, _, _ = net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    t_fwd, _ = _timed(lambda: net.road_to_world(smp["road_id"], smp["s"], smp["t"]), repeat)
    t, proj = _timed(lambda: net.world_to_road(x, y, threads=threads), repeat)
    ok = (proj.road_id == smp["road_id"]) | (proj.n_candidates > 1)
    multi = float(np.mean(proj.n_candidates > 1))
    base_t = None  # the baseline's time for all n points (measured on nb of them, scaled)
    base_note = ""
    if baseline_points:
        nb = min(n, baseline_points)
        tb, broad, bs, bt = shapely_baseline(net, x[:nb], y[:nb])
        base_t = tb * n / nb
        ids = np.array(list(net.roads), dtype=object)
        same = ids[np.maximum(broad, 0)] == smp["road_id"][:nb]
        ds = np.abs(bs - smp["s"][:nb])[same]
        dt = np.abs(bt - np.abs(smp["t"][:nb]))[same]
        base_note = (f"shapely baseline {nb / tb:,.0f} points/s on the first {nb:,} points; its nearest "
                     f"road is the true one for {100 * same.mean():.1f} %, there |ds| p99 "
                     f"{np.percentile(ds, 99):.2g} m, ||t| error| p99 {np.percentile(dt, 99):.2g} m")
    ratio = f"  {base_t / t:.1f}x the shapely baseline" if base_t else ""
    print(
        f"{path.name:45s} world->road {n / t:12,.0f} points/s  ({n:,} points, {t:.3f} s, "
        f"{100 * multi:.1f} % on several roads, {100 * ok.mean():.2f} % consistent){ratio}"
    )
    if base_t:
        print(f"{'':45s}   {base_note}")
    print(f"{'':45s} road->world {n / t_fwd:12,.0f} points/s")
    base_note = "; " + base_note if base_note else ""
    name = _short(path)
    return [
        _row(f"opendrive.world_to_road.{name}", n, t, base_t,
             f"all candidates, lane, s, t exact; {100 * multi:.1f} % on several roads{base_note}"),
        _row(f"opendrive.road_to_world.{name}", n, t_fwd, None, "x, y, z, heading"),
    ]


def bench_fit(repeat: int) -> list[dict]:
    """Fit a 600 m, 3-lane road (line, clothoid, arc) to lane-centre points with 5 cm noise."""
    from aveas_format.opendrive.builder import curved_highway
    from aveas_format.opendrive.roadfit import fit_road

    truth = load_map(curved_highway(length=600.0, radius=250.0, straight=120.0, spiral=80.0, lanes_right=3))
    rng = np.random.default_rng(0)
    s = np.arange(0.0, 600.0 + 1e-9, 2.0)
    lines = []
    for tt in (-1.75, -5.25, -8.75):
        x, y, _, _ = truth.road_to_world("1", s, np.full(len(s), tt))
        lines.append(np.column_stack([x, y]) + rng.normal(0, 0.05, (len(s), 2)))
    t, fit = _timed(lambda: fit_road(lines), repeat)
    n = sum(len(a) for a in lines)
    kinds = ", ".join(f"{k} {v}" for k, v in fit.reference_line.kinds.items())
    print(f"fit_road: {n} points of 3 lane centres (600 m, 5 cm noise) in {1e3 * t:.0f} ms -> {kinds}, "
          f"reference RMS {100 * fit.rms:.1f} cm")
    return [_row("opendrive.fit_road", n, t, None, f"600 m, 3 lane centres, 5 cm noise -> {kinds}")]


def main(argv: list[str] | None = None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--maps", type=Path, default=DEFAULT_MAPS, help="folder of .xodr maps")
    ap.add_argument("--points", type=int, default=1_000_000, help="points per throughput run")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None, help="worker threads (default: up to 4)")
    ap.add_argument("--baseline-points", type=int, default=50_000,
                    help="points for the shapely baseline (its first N of the same points; 0: skip)")
    # tolerate the flags of a calling runner (benchmarks/run.py calls main() without arguments)
    args, _ = ap.parse_known_args([] if argv is None and __name__ != "__main__" else argv)
    maps = sorted(args.maps.glob("*.xodr"))
    rows: list[dict] = []
    print(f"OpenDRIVE engine benchmark ({os.cpu_count()} CPUs)\n")
    if maps:
        rows += bench_load(maps, args.repeat)
        print()
        for name in THROUGHPUT_MAPS:
            path = args.maps / name
            if path.exists():
                rows += bench_projection(path, args.points, args.repeat, args.threads, args.baseline_points)
    else:
        print(f"no .xodr maps in {args.maps}: load and projection benchmarks skipped")
    print()
    rows += bench_fit(args.repeat)
    return rows


if __name__ == "__main__":
    main()
