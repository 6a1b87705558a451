"""Derivations: kinematics on 3M samples, interactions (1D + 2D) on a highway recording, PET on a
junction scene. commonroad-crime (the reference peer) is timed on the same scene when installed.

Targets (issue 5, 2-core machine): kinematics on 3M samples in a few seconds.
"""

from __future__ import annotations

import time

import numpy as np


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def _row(name, n, t, note, base=None):
    return {"benchmark": name, "rows": int(n), "seconds": round(t, 3),
            "rows_per_s": round(n / t) if t > 0 else None,
            "baseline_s": None if base is None else round(base, 3),
            "speedup_vs_baseline": None if base is None else round(base / t, 1), "note": note}


def junction_scene(n_per_stream: int = 60, rate_hz: float = 25.0, seed: int = 3):
    """Two perpendicular streams of cars crossing at the origin (off the test map's road):
    eastbound at ~12 m/s and northbound at ~10 m/s, headways 2-6 s."""
    from aveas_format.mapref.build import build_recording
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sample import SITE_CRS

    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    pids, ts, xs, ys, hs, vxs, vys = [], [], [], [], [], [], []
    k = 0
    for stream in (0, 1):
        t_enter = np.cumsum(rng.uniform(2.0, 6.0, n_per_stream))
        v = rng.uniform(9.0, 13.0, n_per_stream) * (1.2 if stream == 0 else 1.0)
        for te, vi in zip(t_enter, v):
            t = np.arange(np.ceil(te / dt), np.floor((te + 80.0 / vi) / dt)) * dt
            d = -40.0 + vi * (t - te)
            x, y = (d, np.full_like(d, -1.0)) if stream == 0 else (np.full_like(d, 1.0), d)
            pids.append(np.full(len(t), k))
            ts.append(t)
            xs.append(x)
            ys.append(y + 5000.0)
            hs.append(np.full(len(t), 0.0 if stream == 0 else np.pi / 2))
            vxs.append(np.full(len(t), vi if stream == 0 else 0.0))
            vys.append(np.full(len(t), 0.0 if stream == 0 else vi))
            k += 1
    n = sum(len(a) for a in ts)
    states = {"participant_id": np.concatenate(pids), "time": np.concatenate(ts),
              "x": np.concatenate(xs) + rng.normal(0, 0.05, n),
              "y": np.concatenate(ys) + rng.normal(0, 0.05, n), "heading": np.concatenate(hs),
              "vx": np.concatenate(vxs), "vy": np.concatenate(vys),
              "x_std": np.full(n, 0.05), "y_std": np.full(n, 0.05)}
    parts = {"participant_id": np.arange(k), "class": ["car"] * k,
             "length": rng.uniform(4.0, 5.0, k), "width": rng.uniform(1.7, 1.9, k)}
    return build_recording(map_source=straight_highway(200, geo_reference=SITE_CRS),
                           participants=parts, states=states, method="infrastructure_camera",
                           partner="bench", reference=False)


def bench_kinematics(n_tracks: int = 1000, n_steps: int = 3000) -> list[dict]:
    """Kinematics on ``n_tracks x n_steps`` samples (25 Hz, position std 0.1 m): fixed process
    noise, ``auto`` (maximum likelihood per window) and Savitzky-Golay. Runs alone with
    ``python -c 'from benchmarks.bench_derive import bench_kinematics as b; print(b())'``."""
    from aveas_format.derive.kinematics import KinematicsParams, estimate
    from aveas_format.sample import synthetic_states

    rows = []
    s = synthetic_states(n_tracks, n_steps)
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x, y = s.column("x").to_numpy(), s.column("y").to_numpy()
    n = len(t)
    ones = np.full(n, 0.1)
    zero = np.zeros(n)
    for q, label in ((1.0, "fixed q = 1 m²/s⁵"),
                     ("auto", "q by maximum likelihood per window (12 decades + 1 bisection)")):
        dt, _ = _timed(lambda: estimate(pid, t, x, y, ones, ones, zero, None,
                                        KinematicsParams(jerk_density=q)))
        rows.append(_row("derive.kinematics", n, dt, f"CA Kalman + RTS, {label}; "
                         f"{n_tracks:,} tracks x {n_steps:,} samples, lockstep over tracks"))
    dt, _ = _timed(lambda: estimate(pid, t, x, y, ones, ones, zero, None,
                                    KinematicsParams(method="savitzky_golay")))
    rows.append(_row("derive.kinematics_savgol", n, dt, "Savitzky-Golay option"))
    return rows


def main(n_vehicles: int = 1000, duration_s: float = 600.0) -> list[dict]:
    from aveas_format.derive import derive
    from aveas_format.sample import highway_scene

    rows = bench_kinematics()
    # --- interactions on a highway recording ------------------------------------------------------
    tb, rec = _timed(lambda: highway_scene(n_vehicles=n_vehicles, duration_s=duration_s,
                                           length_m=1000.0, seed=11))
    m = rec.states.num_rows
    derive(rec, only="kinematics", jerk_density=1.0)
    dt, _ = _timed(lambda: derive(rec, only="interactions"))
    pairs = rec.derived["interactions"].num_rows
    crime = _crime_seconds(rec)
    rows.append(_row("derive.interactions", m, dt,
                     f"{n_vehicles} vehicles, {duration_s:g} s at 25 Hz ({m:,} states, "
                     f"{pairs:,} relation rows; lane 1D + 2D boxes with 32-sample std); scene "
                     f"built in {tb:.1f} s; commonroad-crime "
                     + ("installed, scene not converted: no ratio" if _crime_installed()
                        else "not installed: no ratio"), crime))
    # --- PET on a junction scene ----------------------------------------------------------------
    jr = junction_scene()
    dt, _ = _timed(lambda: derive(jr, only="encroachments"))
    rows.append(_row("derive.encroachments", jr.states.num_rows, dt,
                     f"two crossing streams, {jr.participants.num_rows} cars, "
                     f"{jr.derived['encroachments'].num_rows} conflicts (swept paths, "
                     "in-frame entry/exit; columnar occupancy and pairing)"))
    import shapely

    box = shapely.box(-3.0, 4997.0, 3.0, 5003.0).wkt  # the crossing, passed by every car
    dt, _ = _timed(lambda: derive(jr, only="encroachments", conflict_areas=[box]))
    rows.append(_row("derive.encroachments_area", jr.states.num_rows, dt,
                     f"same scene, one explicit conflict area: "
                     f"{jr.derived['encroachments'].num_rows} pairs within max_pet"))
    return rows


def _crime_seconds(rec) -> float | None:
    """commonroad-crime's TTC on the same scene: an optional extra that needs the scene converted
    to a CommonRoad scenario; this benchmark does not convert scenes, so no ratio is reported
    (the note says whether the package is installed)."""
    return None


def _crime_installed() -> bool:
    import importlib.util

    return importlib.util.find_spec("commonroad_crime") is not None


if __name__ == "__main__":
    for r in main():
        print(r)
