"""Figures of docs/derive.md: ``python tools/derive_figures.py [OUTDIR]`` (``make docs`` runs it).

The scenes and their derivation are made here; the figures are drawn by
:mod:`aveas_format.plot.derive`.

- ``derive_cut_in_ttc.png``: TTC over time for a cut-in: while the cutting car is a neighbour its
  TTC is the exact 2D box TTC, once it is in the ego lane the lane-based 1D TTC (with 1-sigma bands).
- ``derive_ttc_drac.png``: TTC and DRAC of a follower to a leader that brakes hard, with their
  1-sigma bands (the follower reacts after 0.8 s).
- ``derive_kinematics.png``: derived longitudinal/lateral acceleration with its 1-sigma band
  against the truth for one lane-changing car of the noisy synthetic highway (sigma 0.1 m, 25 Hz).
- ``derive_event.png``: one derived conflict (a cut-in with a true minimum TTC of 1 s, aerial
  noise): its paths on the map and the pair's TTC and DRAC (:func:`aveas_format.plot.criticality.
  event_figure`).
- ``derive_collision_reliability.png``: the collision probability's reliability diagram from
  ``benchmarks/bench_near_miss.py``'s calibration (the numbers are printed).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from aveas_format.safeio import save_figure_atomic


def _two_cars(t: np.ndarray, x, y, heading, vx, vy):
    """A recording of cars 0 and 1 on a straight 3-lane motorway from their states at times ``t``
    (each array: car 0's samples, then car 1's), with the std of a good aerial tracker."""
    from aveas_format.mapref.build import build_recording
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sample import SITE_CRS

    m = 2 * len(t)
    states = {"participant_id": np.repeat([0, 1], len(t)), "time": np.tile(t, 2), "x": x, "y": y,
              "heading": heading, "vx": vx, "vy": vy, "x_std": np.full(m, 0.1),
              "y_std": np.full(m, 0.1), "vx_std": np.full(m, 0.2), "vy_std": np.full(m, 0.2),
              "heading_std": np.full(m, 0.01)}
    parts = {"participant_id": [0, 1], "class": ["car", "car"], "length": [4.6, 4.8],
             "width": [1.85, 1.9], "length_std": [0.1, 0.1], "width_std": [0.05, 0.05]}
    return build_recording(map_source=straight_highway(1000, geo_reference=SITE_CRS),
                           participants=parts, states=states, method="aerial", partner="docs")


def cut_in_recording():
    """Ego (id 0) in lane -1 at 30 m/s; a car (id 1) 30 m ahead (centres) in lane -2 at 26 m/s changes into
    lane -1 between t = 2 s and t = 5 s (cosine profile)."""
    dt = 0.04
    t = np.arange(0, 8.0 + dt / 2, dt)
    n = len(t)
    x0 = 50.0 + 30.0 * t
    u = np.clip((t - 2.0) / 3.0, 0, 1)
    y1 = -5.25 + 3.5 * 0.5 * (1 - np.cos(np.pi * u))
    vy1 = np.where((u > 0) & (u < 1), 3.5 * 0.5 * np.pi * np.sin(np.pi * u) / 3.0, 0.0)
    x1 = 80.0 + 26.0 * t
    return _two_cars(t, np.r_[x0, x1], np.r_[np.full(n, -1.75), y1],
                     np.r_[np.zeros(n), np.arctan2(vy1, 26.0)],
                     np.r_[np.full(n, 30.0), np.full(n, 26.0)], np.r_[np.zeros(n), vy1])


def cut_in_figure(path: Path) -> Path:
    from aveas_format.derive import derive
    from aveas_format.plot.derive import ttc_figure

    rec = cut_in_recording()
    derive(rec, only="interactions")
    fig = ttc_figure(rec.derived["interactions"], 0, 1, highlight=(2.0, 5.0, "lane change of the other car"),
                     xlim=(0.0, 8.0), ylabel="TTC of ego to the cutting car (s)",
                     title="Cut-in: ego 30 m/s, cutting car 26 m/s, 30 m ahead (centres)")
    return save_figure_atomic(fig, path, dpi=120)


def braking_leader_recording():
    """A leader (id 1) 20 m ahead (centres) of a follower (id 0), both at 25 m/s in lane -1; the
    leader brakes at 6 m/s² from t = 2 s, the follower at 7 m/s² from t = 2.8 s (0.8 s reaction)
    until both stand, 2.7 m apart. Measured positions with 0.1 m std and velocities with 0.2 m/s
    std at 25 Hz."""
    dt = 0.04
    t = np.arange(0, 9.0 + dt / 2, dt)
    m = 2 * len(t)

    def motion(x0, v0, t_brake, a):
        tb = np.clip(t - t_brake, 0.0, v0 / a)
        v = v0 - a * tb
        return x0 + v0 * np.minimum(t, t_brake) + v0 * tb - 0.5 * a * tb * tb, v

    xf, vf = motion(50.0, 25.0, 2.8, 7.0)
    xl, vl = motion(70.0, 25.0, 2.0, 6.0)
    rng = np.random.default_rng(4)
    return _two_cars(t, np.r_[xf, xl] + rng.normal(0, 0.1, m), -1.75 + rng.normal(0, 0.1, m),
                     np.zeros(m), np.r_[vf, vl] + rng.normal(0, 0.2, m), rng.normal(0, 0.2, m))


def ttc_drac_figure(path: Path) -> Path:
    from aveas_format.derive import derive
    from aveas_format.plot.derive import ttc_drac_figure as draw

    rec = braking_leader_recording()
    derive(rec, only=["kinematics", "interactions"])
    fig = draw(rec.derived["interactions"], 0, 1, xlim=(0.0, 9.0),
               title="Leader brakes at 6 m/s² (t = 2 s), follower at 7 m/s² (t = 2.8 s)")
    return save_figure_atomic(fig, path, dpi=120)


def kinematics_figure(path: Path) -> Path:
    from aveas_format.derive import derive
    from aveas_format.plot.derive import acceleration_figure
    from aveas_format.sample import highway_scene

    rec, truth = highway_scene(n_vehicles=60, duration_s=30.0, return_truth=True)
    derive(rec, only="kinematics")
    k = rec.derived["kinematics"]
    # the car with the largest lateral acceleration (a lane change)
    car = int(k.column("participant_id").to_numpy()[np.argmax(np.abs(truth["ay"]))])
    fig = acceleration_figure(k, car, truth=truth,
                              title=f"CA Kalman + RTS from positions with σ = 0.1 m at 25 Hz (car {car})")
    return save_figure_atomic(fig, path, dpi=120)


def event_figure(path: Path) -> Path:
    from aveas_format.derive import derive
    from aveas_format.derive.events import worst_events
    from aveas_format.plot.criticality import event_figure as draw
    from aveas_format.sample.scenes import conflict_scene

    rec = conflict_scene("cut_in", 1.0, method="aerial", position_std=0.2, seed=4)
    derive(rec)
    return save_figure_atomic(draw(rec, worst_events(rec.events, 1)[0]), path, dpi=110)


def reliability_figure(path: Path, n_per: int = 8) -> Path:
    import importlib.util
    import json

    from aveas_format.plot.criticality import reliability_figure as draw

    bench = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_near_miss.py"
    spec = importlib.util.spec_from_file_location("bench_near_miss", bench)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    cal = mod.collision_calibration(n_per=n_per)
    rows = cal.pop("rows")
    print(json.dumps(cal, indent=1))
    fig = draw([r["p"] for r in rows], [r["outcome"] for r in rows],
               title=f"Collision probability, {len(rows)} encounters (aerial and LiDAR noise): "
               "reliability (95 % Wilson)")
    return save_figure_atomic(fig, path, dpi=120)


def main(outdir: str | Path | None = None) -> list[Path]:
    out = Path(outdir) if outdir else Path(__file__).resolve().parents[1] / "docs" / "figures"
    out.mkdir(parents=True, exist_ok=True)
    return [cut_in_figure(out / "derive_cut_in_ttc.png"),
            ttc_drac_figure(out / "derive_ttc_drac.png"),
            kinematics_figure(out / "derive_kinematics.png"),
            event_figure(out / "derive_event.png"),
            reliability_figure(out / "derive_collision_reliability.png")]


if __name__ == "__main__":
    for p in main(sys.argv[1] if len(sys.argv) > 1 else None):
        print(p)
