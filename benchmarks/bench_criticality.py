"""Criticality measures (issue 20): per 10^6 follower pairs, and all measures for an hour of a busy
highway streamed by time window.

1. ``pairs``: TTC + DRAC + MTTC + PSD, each with its std, for 10^6 follower/leader pairs: ours
   (:func:`aveas_format.derive.interactions._ttc.follower_leader_metrics`, which also computes THW,
   DHW and MDRAC: NumPy in cache-sized chunks) against a straightforward vectorised NumPy
   implementation of the same formulas written below (whole arrays, MTTC piece by piece, the same
   analytic std: the baseline of the ratios) and the same with the MTTC std by central finite
   differences (as the derivations did before), all in one run; warm calls (best of 5).
2. ``highway_hour``: ~100 concurrent vehicles at 25 Hz for 1 h (~9M states, a vectorised
   generator below) written as a recording, then every measure (kinematics, interactions with
   DRAC/MDRAC/PSD and their std, conflicts, the events — episodes by evidence and persistence,
   encounters, a collision probability each — and the criticality summary) streamed by time
   window (:func:`aveas_format.derive.streamed.derive_by_windows`) on 2 worker processes, in a
   fresh process whose peak memory (VmHWM) is reported. Target: <= 120 s. ``events``: the cost
   of the events alone — the same derivation without and with them in interleaved pairs on one
   recording, the CPU ratio (median of the pairs).
3. ``sample``: the real pipeline (``derive(rec, only="interactions")``) on the sample highway,
   with the share of its time spent in the follower/leader metrics.

Run alone: ``.venv/bin/python benchmarks/bench_criticality.py [pairs|sample|hour [SECONDS
[W1,W2...]]|events [SECONDS [WINDOW [PAIRS]]]]`` (``hour``: 60-s and 300-s windows on the same
recording, the CPU ratio between them; ``events``: default 600 s, 300-s windows, 2 pairs).
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


# --- the baseline: straightforward NumPy ----------------------------------------------------------

def _mttc_baseline(g, vf, af, vl, al):
    """MTTC with constant accelerations, vehicles stop rather than reverse: three pieces between
    the stop times, the first root of each quadratic, whole arrays."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        Tf = np.where((af < 0) & (vf > 0), -vf / af, np.where((vf <= 0) & (af <= 0), 0.0, np.inf))
        Tl = np.where((al < 0) & (vl > 0), -vl / al, np.where((vl <= 0) & (al <= 0), 0.0, np.inf))
        b1, b2 = np.minimum(Tf, Tl), np.maximum(Tf, Tl)
        out = np.full(g.shape, np.inf)
        for lo, hi in ((np.zeros_like(g), b1), (b1, b2), (b2, np.full_like(g, np.inf))):
            mid = np.where(np.isfinite(hi), 0.5 * (lo + hi), lo + 1.0)
            fm, lm = mid < Tf, mid < Tl
            xf0 = np.where(fm, 0.0, np.nan_to_num(vf * Tf + 0.5 * af * Tf * Tf, posinf=0.0))
            xl0 = np.where(lm, 0.0, np.nan_to_num(vl * Tl + 0.5 * al * Tl * Tl, posinf=0.0))
            A = g + xl0 - xf0
            B = np.where(lm, vl, 0.0) - np.where(fm, vf, 0.0)
            C = np.where(lm, 0.5 * al, 0.0) - np.where(fm, 0.5 * af, 0.0)
            hi_ = np.where(np.isfinite(hi), hi, 1e300)
            g0 = A + B * lo + C * lo * lo
            disc = B * B - 4 * A * C
            sq = np.sqrt(np.maximum(disc, 0.0))
            lin = np.abs(C) < 1e-12
            r_lin = np.where(B < 0, -A / B, np.inf)
            r1 = np.where(disc >= 0, (-B - sq) / (2 * C), np.inf)
            r2 = np.where(disc >= 0, (-B + sq) / (2 * C), np.inf)
            cand = np.stack([np.where(lin, r_lin, r1), np.where(lin, np.inf, r2)])
            cand = np.where((cand >= lo) & (cand <= hi_), cand, np.inf).min(axis=0)
            r = np.where(g0 <= 0, lo, cand)
            out = np.where((lo < hi) & (r < out), r, out)
        return np.where(g < 0, np.inf, out)


def baseline(g, gv, vf, af, vfv, afv, vl, al, vlv, alv, d_max=3.4, analytic=False):
    """TTC, DRAC, MTTC and PSD with their std (delta method), whole arrays."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        dv = vf - vl
        dvv = vfv + vlv
        ttc = np.where((dv > 0) & (g >= 0), g / dv, np.inf)
        ttc_std = np.sqrt(gv / dv ** 2 + g ** 2 * dvv / dv ** 4)
        drac = np.where((dv > 0) & (g > 0), dv ** 2 / (2 * g), np.nan)
        drac_std = np.sqrt((dv / g) ** 2 * dvv + (dv ** 2 / (2 * g ** 2)) ** 2 * gv)
        psd = np.where(vf > 0, 2 * d_max * g / vf ** 2, np.nan)
        psd_std = np.sqrt((2 * d_max / vf ** 2) ** 2 * gv + (4 * d_max * g / vf ** 3) ** 2 * vfv)
        mttc = _mttc_baseline(g, vf, af, vl, al)
        args = [g, vf, af, vl, al]
        var = np.zeros(len(g))
        if analytic:
            Tf = np.where((af < 0) & (vf > 0), -vf / af, np.where((vf <= 0) & (af <= 0), 0, np.inf))
            Tl = np.where((al < 0) & (vl > 0), -vl / al, np.where((vl <= 0) & (al <= 0), 0, np.inf))
            tf, tl = np.minimum(mttc, Tf), np.minimum(mttc, Tl)
            rate = (vl + al * tl) - (vf + af * tf)
            var = (gv + tf ** 2 * vfv + tf ** 4 / 4 * afv + tl ** 2 * vlv + tl ** 4 / 4 * alv) / rate ** 2
        else:
            for k, v in enumerate((gv, vfv, afv, vlv, alv)):
                h = np.maximum(1e-4, 1e-3 * np.abs(args[k]))
                up, dn = list(args), list(args)
                up[k], dn[k] = args[k] + h, args[k] - h
                d = (_mttc_baseline(*up) - _mttc_baseline(*dn)) / (2 * h)
                var += np.where(np.isfinite(d), d * d * v, 0.0)
        mttc_std = np.where(np.isfinite(mttc), np.sqrt(var), np.nan)
    return ttc, ttc_std, drac, drac_std, mttc, mttc_std, psd, psd_std


def _pairs(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    vf = rng.uniform(5, 40, n)
    return dict(g=rng.uniform(1, 80, n), gv=np.full(n, 0.04), vf=vf, af=rng.normal(0, 1, n),
                vfv=np.full(n, 0.01), afv=np.full(n, 0.04), vl=vf - rng.normal(1, 3, n),
                al=rng.normal(0, 1.5, n), vlv=np.full(n, 0.01), alv=np.full(n, 0.04))


def bench_pairs(n: int = 1_000_000, repeat: int = 5) -> list[dict]:
    """Ours and the two baselines in one run; the ratio against the baseline with the same
    analytic derivatives."""
    from aveas_format.derive.interactions._ttc import PASSED_THROUGH, follower_leader_metrics

    p = _pairs(n)

    def ours():
        return follower_leader_metrics(p["g"], p["gv"], np.full(n, 4.5),
                                       (p["vf"], p["af"], p["vfv"], p["afv"]),
                                       (p["vl"], p["al"], p["vlv"], p["alv"]))

    cpu = {}

    def best(fn, name=None):
        """Best wall time of ``repeat`` warm calls (and, under ``name``, the best CPU time of
        this thread: less sensitive to other processes on the cores than the wall time)."""
        fn()  # warm: the allocator's arrays mapped
        ts, cs = [], []
        for _ in range(repeat):
            t0, c0 = time.perf_counter(), time.thread_time()
            r = fn()
            ts.append(time.perf_counter() - t0)
            cs.append(time.thread_time() - c0)
        if name:
            cpu[name] = min(cs)
        return min(ts), r

    t_np, m = best(ours, "ours")
    t_an, b = best(lambda: baseline(**p, analytic=True), "baseline")
    t_fd, _ = best(lambda: baseline(**p))
    k_out = len(m) - len(PASSED_THROUGH)
    t_floor, _ = best(lambda: [np.full(n, 1.0) for _ in range(k_out)])
    # the same numbers as the baseline's
    same = {k: bool(np.allclose(m[k], v, rtol=1e-9, equal_nan=True)) for k, v in
            (("ttc", b[0]), ("drac", b[2]), ("ttc_ca", b[4]), ("psd", b[6]))}
    return [{"benchmark": "criticality.pairs", "rows": n, "baseline_s": round(t_an, 3),
             "seconds": round(t_np, 3), "rows_per_s": round(n / t_np),
             "speedup_vs_baseline": round(t_an / t_np, 1),
             "note": (f"{n:,} follower pairs, TTC + DRAC + MTTC + PSD with std (ours also THW, "
                      f"DHW, MDRAC); baseline: straightforward NumPy with the same analytic std "
                      f"{t_an:.3f} s; with the MTTC std by central differences {t_fd:.3f} s -> "
                      f"{t_fd / t_np:.1f}x; values equal to the baseline's: {same}; writing "
                      f"{k_out} fresh output arrays alone {t_floor:.3f} s; CPU time (this "
                      f"thread, best of {repeat}): ours {cpu['ours']:.3f} s, baseline "
                      f"{cpu['baseline']:.3f} s -> {cpu['baseline'] / cpu['ours']:.1f}x")}]


def bench_sample(repeat: int = 3) -> list[dict]:
    """The real pipeline on the sample highway (``sample.highway_scene``: 60 vehicles, 30 s at
    25 Hz): ``derive(rec, only="interactions")`` with the time spent in the follower/leader
    metrics (``follower_leader_metrics`` timed where the pipeline calls it). Best of ``repeat``
    after a warm-up."""
    from aveas_format.derive import derive
    from aveas_format.derive.interactions import _pairs as pairs_mod
    from aveas_format.sample import highway_scene

    rec = highway_scene()
    n_states = rec.states.num_rows
    inner = pairs_mod.follower_leader_metrics
    spent = {"s": 0.0, "pairs": 0}

    def timed(*a, **k):
        t0 = time.perf_counter()
        r = inner(*a, **k)
        spent["s"] += time.perf_counter() - t0
        spent["pairs"] += len(a[0])
        return r

    best = None
    pairs_mod.follower_leader_metrics = timed
    try:
        for i in range(repeat + 1):  # the first round warms up
            spent.update(s=0.0, pairs=0)
            t0 = time.perf_counter()
            derive(rec, only="interactions")
            total = time.perf_counter() - t0
            if i and (best is None or total < best[0]):
                best = (total, spent["s"], spent["pairs"])
    finally:
        pairs_mod.follower_leader_metrics = inner
    total, fol, npairs = best
    return [{"benchmark": "criticality.sample_interactions", "rows": n_states,
             "seconds": round(total, 3), "rows_per_s": round(n_states / total),
             "baseline_s": None, "speedup_vs_baseline": None,
             "note": (f"derive(only='interactions') on the sample highway ({n_states:,} states, "
                      f"{rec.derived['interactions'].num_rows:,} interaction rows, {npairs:,} "
                      f"follower/leader pairs): of it the follower measures {fol:.4f} s "
                      f"({100 * fol / total:.1f} %)")}]


# --- an hour of a busy highway ----------------------------------------------------------------------

def highway_hour(path: Path, duration_s: float = 3600.0, concurrent: int = 100,
                 length_m: float = 3000.0, rate_hz: float = 25.0, seed: int = 5,
                 min_headway_s: float = 1.8) -> int:
    """Write a recording of a 3-lane, ``length_m`` straight motorway with ``concurrent`` vehicles
    on it on average for ``duration_s`` (vectorised). Per lane one speed profile (two
    oscillations around the lane's speed) that every vehicle of the lane drives, shifted in
    time by at least ``min_headway_s`` plus its length at the lane's slowest: followers close in
    and fall back as the lane slows down and speeds up, never within ``min_headway_s`` of net
    time headway, so no vehicle drives through another (as ``sample.traffic_scene``'s traffic;
    true conflicts are few on a real highway, and each costs a collision probability: the
    ``events`` benchmark). Positions measured with 0.1 m, velocities with 0.2 m/s of noise.
    Returns the number of states."""
    from aveas_format.mapref.build import build_recording
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sample import SITE_CRS

    rng = np.random.default_rng(seed)
    lanes = np.array([-1, -2, -3])
    share = np.array([0.35, 0.4, 0.25])
    V = np.array([36.0, 30.0, 24.0])
    amp = rng.uniform(0.4, 1.5, (3, 2))
    om = 2 * np.pi / rng.uniform(25.0, 80.0, (3, 2))
    ph = rng.uniform(0, 2 * np.pi, (3, 2))
    vmin, vmax = V - amp.sum(1), V + amp.sum(1)
    l_max = 6.0
    # entry times per lane: the mean gap that gives the lane its share of ``concurrent``, at
    # least the minimum net headway at the lane's fastest plus a length at its slowest
    gap_min = min_headway_s * vmax / vmin + l_max / vmin
    gap_mean = length_m / V / (concurrent * share)
    travel = length_m / vmin
    t_in, lane_i = [], []
    for li in range(3):
        n = int((duration_s + travel[li] + 5.0) / gap_mean[li] * 1.2) + 10
        g = gap_min[li] + rng.exponential(max(gap_mean[li] - gap_min[li], 0.1), n)
        tau = -travel[li] - 5.0 + np.cumsum(g)
        tau = tau[tau < duration_s]
        t_in.append(tau)
        lane_i.append(np.full(len(tau), li))
    order = np.argsort(np.concatenate(t_in), kind="stable")
    t_in = np.concatenate(t_in)[order]
    li = np.concatenate(lane_i)[order]
    n_veh = len(t_in)
    lane = lanes[li]
    dt = 1.0 / rate_hz
    # each vehicle's samples while it is on the road and within the hour
    t_end = t_in + travel[li] + 1.0
    k0 = np.ceil(np.maximum(t_in, 0) / dt).astype(np.int64)
    k1 = np.floor(np.minimum(t_end, duration_s - dt) / dt).astype(np.int64)
    cnt = np.maximum(k1 - k0 + 1, 0)
    veh = np.repeat(np.arange(n_veh), cnt)
    first = np.cumsum(cnt) - cnt
    t = (k0[veh] + np.arange(int(cnt.sum())) - first[veh]) * dt
    tau = t - t_in[veh]
    lv = li[veh]
    s = V[lv] * tau
    v = V[lv].copy()
    for j in range(2):
        a_, w_, p_ = amp[lv, j], om[lv, j], ph[lv, j]
        s -= a_ / w_ * (np.cos(w_ * tau + p_) - np.cos(p_))
        v += a_ * np.sin(w_ * tau + p_)
    on = (s > 1.0) & (s < length_m - 1.0)
    veh, t, s, v = veh[on], t[on], s[on], v[on]
    y = (lane[veh] + 0.5) * 3.5
    n = len(t)
    L = np.clip(rng.normal(4.6, 0.4, n_veh), 3.5, l_max)
    Wd = np.clip(rng.normal(1.85, 0.08, n_veh), 1.6, 2.1)
    states = {"participant_id": veh, "time": t, "x": s + rng.normal(0, 0.1, n),
              "y": y + rng.normal(0, 0.1, n), "heading": rng.normal(0, 0.01, n),
              "vx": v + rng.normal(0, 0.2, n), "vy": rng.normal(0, 0.2, n),
              "x_std": np.full(n, 0.1), "y_std": np.full(n, 0.1),
              "vx_std": np.full(n, 0.2), "vy_std": np.full(n, 0.2),
              "heading_std": np.full(n, 0.01)}
    ids = np.unique(veh)
    parts = {"participant_id": ids, "class": ["car"] * len(ids), "length": L[ids],
             "width": Wd[ids], "length_std": np.full(len(ids), 0.1),
             "width_std": np.full(len(ids), 0.05)}
    rec = build_recording(map_source=straight_highway(length_m, lanes_right=3,
                                                      geo_reference=SITE_CRS),
                          participants=parts, states=states, method="aerial", partner="bench",
                          reference=True)
    rec.write(path, overwrite=True)
    return n


def _hour_child(path: str, workers: int, window_s: float, events: bool = True) -> None:
    """In a fresh process: derive the recording by windows into a new recording (what
    ``aveas-format derive REC --window S -o OUT`` does; ``events`` False: without the events);
    print seconds, CPU time and peak memory."""
    from aveas_format.derive.streamed import write_by_windows

    t0 = time.perf_counter()
    info = write_by_windows(path, Path(path).parent / "derived.aveas", window_s=window_s,
                            workers=workers, overwrite=True, events=events)
    secs = time.perf_counter() - t0
    import resource

    cpu = sum(getattr(resource.getrusage(w), f) for w in (resource.RUSAGE_SELF,
                                                          resource.RUSAGE_CHILDREN)
              for f in ("ru_utime", "ru_stime"))
    hwm = next((int(ln.split()[1]) for ln in Path("/proc/self/status").read_text().splitlines()
                if ln.startswith("VmHWM")), None)
    print(json.dumps({"seconds": secs, "cpu_s": cpu, "vmhwm_kb": hwm, **info}))


def _run_child(path: Path, workers: int, window_s: float, events: bool = True) -> dict:
    """:func:`_hour_child` in a fresh process, with the load average at its start and end."""
    with open("/proc/loadavg") as f:
        load0 = f.read().split()[0]
    res = subprocess.run([sys.executable, __file__, "_child", str(path), str(workers),
                          str(window_s), "1" if events else "0"], capture_output=True, text=True,
                         check=False)
    if res.returncode != 0:
        raise RuntimeError(res.stderr[-3000:])
    info = json.loads(res.stdout.strip().splitlines()[-1])
    with open("/proc/loadavg") as f:
        info["load"] = f"{load0}-{f.read().split()[0]}"
    return info


def bench_events(duration_s: float = 600.0, window_s: float = 300.0, pairs: int = 2,
                 workers: int = 2) -> list[dict]:
    """The cost of the events in the streamed derivation: the highway (:func:`highway_hour`) of
    ``duration_s`` derived by ``window_s`` windows without and with the events, in ``pairs``
    interleaved pairs of fresh processes; the ratio of their CPU times (process and workers),
    median of the pairs."""
    with tempfile.TemporaryDirectory(prefix="aveas-bench-events-") as d:
        path = Path(d) / "hour.aveas"
        n = highway_hour(path, duration_s=duration_s)
        runs = [(_run_child(path, workers, window_s, False), _run_child(path, workers, window_s))
                for _ in range(pairs)]
    ratios = [w["cpu_s"] / wo["cpu_s"] for wo, w in runs]
    wo, w = runs[int(np.argsort(ratios)[len(ratios) // 2])]
    ratio = float(np.median(ratios))
    return [{"benchmark": "criticality.highway_events", "rows": n,
             "seconds": round(w["seconds"], 1), "rows_per_s": round(n / w["seconds"]),
             "baseline_s": round(wo["seconds"], 1), "speedup_vs_baseline": round(1 / ratio, 3),
             "note": (f"{duration_s:g} s of the busy highway ({n:,} states), {window_s:g}-s "
                      f"windows on {workers} workers, without and with the events in {pairs} "
                      f"interleaved pairs: CPU time with/without "
                      f"{', '.join(f'{r:.3f}' for r in ratios)} (median {ratio:.3f}x; the median "
                      f"pair {wo['cpu_s']:.0f} s -> {w['cpu_s']:.0f} s); "
                      f"{w.get('events', 0):,} derived events; largest worker "
                      f"{wo['worker_peak_kb'] / 1024:.0f} -> {w['worker_peak_kb'] / 1024:.0f} MB; "
                      f"load average {', '.join(r['load'] for p in runs for r in p)}")}]


def bench_hour(duration_s: float = 3600.0, workers: int = 2,
               windows: tuple[float, ...] | None = None) -> list[dict]:
    """The hour derived by windows of each of ``windows`` s (default: derive --window's default
    and 300 s), each in a fresh process on the same recording; the CPU ratio to the last."""
    from aveas_format.derive.streamed import DEFAULT_WINDOW_S

    windows = windows or (DEFAULT_WINDOW_S, 300.0)
    out, infos = [], []
    with tempfile.TemporaryDirectory(prefix="aveas-bench-hour-") as d:
        path = Path(d) / "hour.aveas"
        t0 = time.perf_counter()
        n = highway_hour(path, duration_s=duration_s)
        tb = time.perf_counter() - t0
        for window_s in windows:
            infos.append((window_s, _run_child(path, workers, window_s)))
    ref_w, ref = infos[-1]
    for window_s, info in infos:
        out.append({
            "benchmark": "criticality.highway_hour", "rows": n,
            "seconds": round(info["seconds"], 1), "rows_per_s": round(n / info["seconds"]),
            "baseline_s": None, "speedup_vs_baseline": None,
            "note": (f"{duration_s:g} s, ~100 concurrent vehicles at 25 Hz ({n:,} states; built "
                     f"and written in {tb:.0f} s); every measure with std and the events "
                     f"({info.get('events', 0):,} derived: episodes by evidence and persistence, "
                     f"encounters, a collision probability each), {info['windows']} "
                     f"windows of {window_s:g} s on {workers} workers; "
                     f"CPU time of the deriving process and its workers {info['cpu_s']:.0f} s "
                     f"(/{workers} = {info['cpu_s'] / workers:.0f} s: the wall time on "
                     f"{workers} idle cores, less the idle gaps; "
                     f"{info['cpu_s'] / ref['cpu_s']:.2f}x the CPU of {ref_w:g}-s windows); "
                     f"{info['interactions']:,} interaction rows, {info['conflicts']:,} conflict "
                     f"rows; written as a recording; peak memory of the deriving process "
                     f"(VmHWM, workers excluded) "
                     f"{info['vmhwm_kb'] / 1024:.0f} MB, largest worker "
                     f"{info['worker_peak_kb'] / 1024:.0f} MB; load average {info['load']} "
                     f"(start-end); target <= 120 s")})
    return out


def main() -> list[dict]:
    return bench_pairs() + bench_sample() + bench_hour()


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "_child":
        _hour_child(sys.argv[2], int(sys.argv[3]), float(sys.argv[4]),
                    len(sys.argv) <= 5 or sys.argv[5] == "1")
    elif len(sys.argv) > 1 and sys.argv[1] == "pairs":
        for r in bench_pairs():
            print(r)
    elif len(sys.argv) > 1 and sys.argv[1] == "sample":
        for r in bench_sample():
            print(r)
    elif len(sys.argv) > 1 and sys.argv[1] == "hour":
        for r in bench_hour(float(sys.argv[2]) if len(sys.argv) > 2 else 3600.0,
                            windows=tuple(float(w) for w in sys.argv[3].split(","))
                            if len(sys.argv) > 3 else None):
            print(r)
    elif len(sys.argv) > 1 and sys.argv[1] == "events":
        a = sys.argv[2:]
        for r in bench_events(float(a[0]) if a else 600.0, float(a[1]) if len(a) > 1 else 300.0,
                              int(a[2]) if len(a) > 2 else 2):
            print(r)
    else:
        for r in main():
            print(r)
