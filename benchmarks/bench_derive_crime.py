"""TTC against the reference peer commonroad-crime 0.4.5 on the same scene (issue 5, optional).

The scene: ``highway_scene(50 vehicles, 8 s at 25 Hz)`` — 50 vehicles x 200 steps on a straight
3-lane motorway. Ours: ``derive`` interactions (lane-based 1D TTC for every leader/follower pair
plus the 2D box TTC of conflicting pairs) over every sample. commonroad-crime: the same trajectories
as a CommonRoad scenario (one lanelet per lane, each vehicle a DynamicObstacle), ``TTC`` per
ego and time step (``compute_criticality``: the minimum over the others); it is timed on a random
subset of ego-steps and extrapolated to all of them (it needs ~20 ms per ego-other pair). The TTCs
of both are compared where both are finite. Without commonroad-crime installed the benchmark says
so. It is not an extra of this package: commonroad-io pins protobuf==3.20.2, which the MCAP
support's protobuf cannot share. To run it, use a separate environment::

    python3.11 -m venv /tmp/crime && /tmp/crime/bin/pip install commonroad-crime==0.4.5 -e .
    PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION=python /tmp/crime/bin/python benchmarks/bench_derive_crime.py
"""

from __future__ import annotations

import time

import numpy as np

N_VEHICLES, DURATION_S, SAMPLE_EGO_STEPS = 50, 8.0, 40


def _scenario(rec):
    """A CommonRoad scenario of the recording (straight road along x, lanes of 3.5 m below y=0)."""
    from commonroad.geometry.shape import Rectangle
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.lanelet import Lanelet, LaneletNetwork
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.scenario import Scenario, ScenarioID
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory

    dt = 1.0 / rec.meta.nominal_rate_hz
    sc = Scenario(dt, ScenarioID(map_name="AVEAS"))
    xs = np.linspace(-100.0, 1100.0, 121)
    lanelets = []
    for k in range(3):
        top, bottom = -3.5 * k, -3.5 * (k + 1)
        lanelets.append(Lanelet(np.c_[xs, np.full_like(xs, top)],
                                np.c_[xs, np.full_like(xs, (top + bottom) / 2)],
                                np.c_[xs, np.full_like(xs, bottom)], 100 + k))
    sc.add_objects(LaneletNetwork.create_from_lanelet_list(lanelets))
    s, p = rec.states, rec.participants
    pid = s.column("participant_id").to_numpy()
    step = np.round(s.column("time").to_numpy() / dt).astype(int)
    x, y, h = (s.column(c).to_numpy() for c in ("x", "y", "heading"))
    vx, vy = s.column("vx").to_numpy(), s.column("vy").to_numpy()
    size = {int(i): (float(L), float(W)) for i, L, W in zip(
        p.column("participant_id").to_numpy(), p.column("length").to_numpy(),
        p.column("width").to_numpy())}
    for q in np.unique(pid):
        idx = np.flatnonzero(pid == q)
        L, W = size[int(q)]
        shape = Rectangle(L, W)
        # CommonRoad trajectories have one state per time step: fill the recording's gaps
        ks = np.arange(step[idx[0]], step[idx[-1]] + 1)
        qx, qy, qh = (np.interp(ks, step[idx], a[idx]) for a in (x, y, h))
        qv = np.interp(ks, step[idx], np.hypot(vx[idx], vy[idx]))
        states = [CustomState(position=np.array([qx[j], qy[j]]), orientation=float(qh[j]),
                              velocity=float(qv[j]), time_step=int(ks[j])) for j in range(len(ks))]
        init = InitialState(position=np.array([qx[0], qy[0]]), orientation=float(qh[0]),
                            velocity=float(qv[0]), acceleration=0.0, yaw_rate=0.0, slip_angle=0.0,
                            time_step=int(ks[0]))
        traj = Trajectory(int(ks[1]), states[1:]) if len(ks) > 1 else None
        pred = TrajectoryPrediction(traj, shape) if traj is not None else None
        sc.add_objects(DynamicObstacle(int(q) + 1, ObstacleType.CAR, shape, init, pred))
    sc.assign_obstacles_to_lanelets()
    return sc, pid, step


def main() -> list[dict]:
    from aveas_format.derive import derive
    from aveas_format.sample import highway_scene

    # noise-free, so that the peer's finite-difference accelerations are the true ones
    rec = highway_scene(n_vehicles=N_VEHICLES, duration_s=DURATION_S, seed=11, position_std=0.0,
                        heading_std=0.0, velocity_std=0.0)
    n = rec.states.num_rows
    t0 = time.perf_counter()
    derive(rec, only=["interactions"])
    ours = time.perf_counter() - t0
    inter = rec.derived["interactions"]
    row = {"benchmark": "derive.ttc_vs_commonroad_crime", "rows": n, "seconds": round(ours, 3),
           "rows_per_s": round(n / ours), "baseline_s": None, "speedup_vs_baseline": None}
    try:
        from commonroad_crime.data_structure.configuration import CriMeConfiguration
        from commonroad_crime.measure.time.ttc import TTC
    except ImportError:
        row["note"] = ("commonroad-crime not installed (see the module docstring); ours: 1D + 2D TTC "
                       "of every pair at every step")
        return [row]
    import logging
    import warnings

    logging.disable(logging.WARNING)
    sc, pid, step = _scenario(rec)
    ip = inter.column("participant_id").to_numpy()
    it = inter.column("time").to_numpy()
    rel = np.array(inter.column("relation").cast("string").to_pylist(), dtype=object)
    times = rec.states.column("time").to_numpy()
    # ego-steps with a leader on a collision course (finite TTC in ours), so the two can be compared
    lead = (rel == "leader") & np.isfinite(inter.column("ttc_ca").to_numpy(zero_copy_only=False))
    key = {(int(a), round(float(b), 6)) for a, b in zip(ip[lead], it[lead])}
    cand = np.array([i for i in range(n) if (int(pid[i]), round(float(times[i]), 6)) in key])
    rng = np.random.default_rng(0)
    pick = rng.choice(cand, size=min(SAMPLE_EGO_STEPS, len(cand)), replace=False)
    ttc_crime, spent = [], 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for i in pick:
            cfg = CriMeConfiguration()
            cfg.update(ego_id=int(pid[i]) + 1, sce=sc)
            t1 = time.perf_counter()
            try:
                v = TTC(cfg).compute_criticality(int(step[i]), verbose=False)
            except Exception:  # noqa: BLE001 — the peer fails on some ego-steps; counted as NaN
                v = np.nan
            spent += time.perf_counter() - t1
            ttc_crime.append(float(v) if v is not None else np.nan)
    crime_all = spent / len(pick) * n  # extrapolated to every ego-step (those timed have leaders)
    # ours at the same ego-steps: the smallest lane TTC (constant accelerations) to its leader
    # the peer assumes constant accelerations: compare with our constant-acceleration variant
    # (and, for reference, our constant-velocity TTC)
    ttc_ca = inter.column("ttc_ca").to_numpy(zero_copy_only=False)
    ttc_cv = inter.column("ttc").to_numpy(zero_copy_only=False)
    times = rec.states.column("time").to_numpy()
    def agreement(ttc: np.ndarray) -> str:
        """Median relative difference where both are below 30 s (the critical range; a large TTC
        of a constant-acceleration model swings with tiny acceleration differences), and how
        often only one of the two finds a TTC below 30 s."""
        rel_diff, only_peer, only_ours = [], 0, 0
        for i, c in zip(pick, ttc_crime):
            m = (ip == pid[i]) & np.isclose(it, times[i]) & (rel == "leader")
            o = np.nanmin(ttc[m]) if m.any() and np.isfinite(ttc[m]).any() else np.inf
            c_crit, o_crit = np.isfinite(c) and c < 30, np.isfinite(o) and o < 30
            if c_crit and o_crit:
                rel_diff.append(abs(c - o) / max(c, 1e-9))
            only_peer += c_crit and not o_crit
            only_ours += o_crit and not c_crit
        med = f"{np.median(rel_diff):.3f}" if rel_diff else "n/a"
        return (f"median rel. difference {med} over {len(rel_diff)} ego-steps with both < 30 s; "
                f"< 30 s only in the peer {only_peer}, only in ours {only_ours}")

    row.update(baseline_s=round(crime_all, 1), speedup_vs_baseline=round(crime_all / ours, 1),
               note=f"commonroad-crime 0.4.5 TTC timed on {len(pick)} ego-steps "
                    f"({spent / len(pick) * 1000:.0f} ms each), extrapolated to all {n}; vs our "
                    f"ttc_ca: {agreement(ttc_ca)}; vs our ttc (constant velocity): "
                    f"{agreement(ttc_cv)}")
    return [row]


if __name__ == "__main__":
    for r in main():
        print(r)
