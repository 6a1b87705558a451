"""Car-following metrics of the fitter (time headway, minimum TTC, acceleration spread), the
generalised fit configuration, and the recovery of W99 cc1 from recorded time headways."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers_common import STRAIGHT_MAP
from hypothesis import given, settings
from hypothesis import strategies as st
from helpers_sim import cli_simulated_recording, small_scenario

from aveas_format.fit import METRICS, FitConfig, fit_desired_speed, fit_parameters
from aveas_format.fit.metrics import per_vehicle
from aveas_format.mapref.build import build_recording
from aveas_format.sim import simulate

RATE = 10.0
STEPS = 50


def following_scene():
    """Four vehicles in the rightmost lane of the straight test map, constant speeds, 5 m long:
    0 (car) leads at 25 m/s; 1 (car) follows 0 at a net gap of 30 m at 25 m/s (THW 1.2 s, steady);
    2 (truck) closes in on 1 at 27 m/s from a net gap of 40 m (TTC 20 s -> 15.1 s at the last
    sample); 3 (car) alone in the left lane."""
    t = np.arange(STEPS) / RATE
    lead0 = 300.0
    fronts = {0: (lead0, 25.0, -8.75), 1: (lead0 - 5 - 30, 25.0, -8.75),
              2: (lead0 - 5 - 30 - 5 - 40, 27.0, -8.75), 3: (200.0, 30.0, -1.75)}
    pid, tt, x, y, vx = [], [], [], [], []
    for p, (x0, v, yy) in fronts.items():
        pid.append(np.full(STEPS, p))
        tt.append(t)
        x.append(x0 - 2.5 + v * t)  # centre = front - length / 2
        y.append(np.full(STEPS, yy))
        vx.append(np.full(STEPS, v))
    n = 4 * STEPS
    states = {"participant_id": np.concatenate(pid).astype(np.int64), "time": np.concatenate(tt),
              "x": np.concatenate(x), "y": np.concatenate(y), "heading": np.zeros(n),
              "vx": np.concatenate(vx), "vy": np.zeros(n), "x_std": np.full(n, 0.05),
              "y_std": np.full(n, 0.05), "heading_std": np.full(n, 0.01),
              "vx_std": np.full(n, 0.1), "vy_std": np.full(n, 0.1)}
    participants = {"participant_id": np.arange(4, dtype=np.int64),
                    "class": np.array(["car", "car", "truck", "car"]), "length": np.full(4, 5.0),
                    "width": np.full(4, 1.8), "length_std": np.full(4, 0.1), "width_std": np.full(4, 0.05)}
    return build_recording(map_source=STRAIGHT_MAP, participants=participants, states=states,
                           partner="test", method="aerial", recording_id="follow",
                           coverage="POLYGON ((0 -12, 1000 -12, 1000 2, 0 2, 0 -12))")


def test_time_headway_of_steady_following():
    rec = following_scene()
    v = METRICS["time_headway"].recorded(rec)
    # only vehicle 1 follows steadily (2 closes at 2 m/s, 0 and 3 have no leader)
    assert len(v["car"]) == 1 and len(v["truck"]) == 0
    assert v["car"][0] == pytest.approx(1.2, abs=0.02)
    # with a wider closing-speed tolerance the truck counts too: its median gap / speed
    v2 = METRICS["time_headway"].recorded(rec, max_closing=3.0, max_thw=2.0)
    assert len(v2["truck"]) == 1
    assert v2["truck"][0] == pytest.approx((40 - 2 * 2.45) / 27, abs=0.02)


def test_min_ttc_and_acceleration_spread():
    rec = following_scene()
    ttc = METRICS["min_ttc"].recorded(rec)
    assert len(ttc["car"]) == 0  # no car closes in on its leader
    assert ttc["truck"] == pytest.approx([(40 - 2 * 4.9) / 2], abs=0.05)
    assert len(METRICS["min_ttc"].recorded(rec, max_ttc=10.0)["truck"]) == 0
    acc = METRICS["a_lon_std"].recorded(rec)
    assert len(acc["car"]) == 3 and len(acc["truck"]) == 1
    assert np.all(acc["car"] < 0.05) and np.all(acc["truck"] < 0.05)  # constant speeds


def test_section_and_minimum_following_time():
    rec = following_scene()
    # the follower drives s in [265, 390]: a section behind it leaves nothing
    assert all(len(v) == 0 for v in METRICS["time_headway"].recorded(rec, s_range=(0.0, 100.0)).values())
    # 5 s of steady following: enough for 4 s, not for 6 s
    assert len(METRICS["time_headway"].recorded(rec, min_following=4.0)["car"]) == 1
    assert len(METRICS["time_headway"].recorded(rec, min_following=6.0)["car"]) == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.floats(-1e3, 1e3)), min_size=1, max_size=60))
def test_per_vehicle_matches_a_loop(rows):
    pid = np.array([r[0] for r in rows], np.int64)
    v = np.array([r[1] for r in rows])
    for how, ref in (("median", np.median), ("min", np.min), ("std", lambda a: np.std(a, ddof=1))):
        u, got = per_vehicle(pid, v, how, min_samples=2)
        want = {p: ref(v[pid == p]) for p in np.unique(pid) if (pid == p).sum() >= 2}
        assert list(u) == sorted(want)
        np.testing.assert_allclose(got, [want[p] for p in u], rtol=1e-9, atol=1e-9)


def test_fit_config_parameters_and_bounds():
    cfg = FitConfig(parameters=["cc1_car", "cc3_truck", "mu_car"], metric="time_headway")
    assert cfg.names == ["cc1_car", "cc3_truck", "mu_car"]
    np.testing.assert_allclose(cfg.bounds_array(), [[0.1, 1.0], [-11.0, -2.0], [100.0, 160.0]])
    sc = cfg.scenario_at(np.array([0.6, -5.0, 120.0]))
    assert sc.cls("car").cf_params["cc1"] == 0.6 and sc.cls("truck").cf_params["cc3"] == -5.0
    assert sc.cls("car").speed_mean_kmh == 120.0
    assert sc.cls("car").w99()["cc0"] == 1.5  # the others keep Vissim's defaults
    assert FitConfig().names == ["mu_car", "sigma_car", "mu_truck", "sigma_truck"]
    with pytest.raises(ValueError, match="parameter 'cc12_car'"):
        FitConfig(parameters=["cc12_car"])
    with pytest.raises(ValueError, match="parameter 'cc1_bus'"):
        FitConfig(parameters=["cc1_bus"])
    with pytest.raises(ValueError, match="metric 'thw'"):
        FitConfig(metric="thw")


def test_fit_stored_before_metric_fields_resumes(sumo, tmp_path):
    """A fit directory written before `metric`/`parameters` existed is resumed, not refused."""
    cfg = FitConfig(scenario=small_scenario(duration=60, length=400, inflow=100), restarts=1, maxfev=5,
                    refine=False, bounds={"mu_car": (115.0, 150.0), "sigma_car": (8.0, 28.0),
                            "mu_truck": (80.0, 100.0), "sigma_truck": (2.0, 12.0)})
    od = tmp_path / "fit"
    od.mkdir()
    old = cfg.model_dump(mode="json")
    for k in ("metric", "parameters", "metric_options"):
        del old[k]
    (od / "config.json").write_text(json.dumps(old))
    res = fit_desired_speed({"car": np.array([125.0, 130.0]), "truck": np.array([88.0])}, cfg,
                            outdir=od, figures=False)
    assert len(res.runs) == 1


def _recorded_headways(cc1: float, seed: int = 7) -> dict[str, np.ndarray]:
    sc = small_scenario(duration=900, seed=seed).with_cf_params("car", cc1=cc1)
    return METRICS["time_headway"].simulated(simulate(sc, recording=True))


def _cc1_recovery(tmp_path, minutes: float, maxfev: int) -> None:
    """'Recorded' time headways of a run with cc1 = 0.9 s for cars (seed 7, 15 min) are fitted back
    (other seed, ``minutes`` of demand per evaluation, bounds 0.3-1.8 s, 2 restarts of
    <= ``maxfev`` evaluations): the best cc1 is within 0.2 s. The car-following metrics go through
    the converter and `derive` on both sides."""
    recorded = _recorded_headways(0.9)
    assert len(recorded["car"]) > 100
    cfg = FitConfig(scenario=small_scenario(duration=60 * minutes), metric="time_headway",
                    parameters=["cc1_car"], bounds={"cc1_car": (0.3, 1.8)}, restarts=2,
                    maxfev=maxfev, xatol=0.02, seed=4, refine_seeds=1, bootstrap=0)
    res = fit_parameters(recorded, cfg, workers=2, outdir=tmp_path / "fit")
    assert len(res.runs) == 2 and not res.failed
    assert abs(res.best["cc1_car"] - 0.9) < 0.2, res.runs
    for f in ("runs.parquet", "best.json", "fit_histogram.png", "fit_parameters.png"):
        assert (tmp_path / "fit" / f).exists()


def test_cc1_recovery_from_time_headways(sumo, tmp_path):
    """5 min per evaluation, <= 10 evaluations per restart (measured: 0.965 s)."""
    _cc1_recovery(tmp_path, minutes=5, maxfev=10)


@pytest.mark.slow
def test_cc1_recovery_from_longer_runs(sumo, tmp_path):
    """10 min per evaluation, <= 20 evaluations per restart (measured: 0.849 s; 5x the time of
    the one above)."""
    _cc1_recovery(tmp_path, minutes=10, maxfev=20)


def test_cli_fit_car_following(sumo, tmp_path):
    from aveas_format.cli import main

    cfg, _ = cli_simulated_recording(tmp_path, 'duration = 300\nseed = 5\n[network]\nlength = 600\n'
                                                'inflow = 100\n')
    with pytest.raises(SystemExit) as e:
        main(["fit", "car-following", str(tmp_path / "rec.aveas"), "-c", str(cfg), "-o",
              str(tmp_path / "fit"), "-r", "1", "--maxfev", "5", "-p", "cc1_car",
              "--option", "max_thw=5", "--bounds", '{"cc1_car": [0.5, 1.5]}', "--surface-seeds", "2",
              "--bootstrap", "3"])
    assert e.value.code == 0
    best = json.loads((tmp_path / "fit" / "best.json").read_text())
    assert 0.5 <= best["cc1_car"] <= 1.5
    assert best["response_surface"]["seeds"] == 2 and set(best["se_seed"]) == {"cc1_car"}
    stored = json.loads((tmp_path / "fit" / "config.json").read_text())
    assert stored["metric"] == "time_headway" and stored["metric_options"] == {"max_thw": 5.0}
    for bad, msg in ((["--option", "max_thw"], "NAME=NUMBER"), (["--option", "foo=1"], "expected one of"),
                     (["-m", "thw"], "--metric 'thw'")):
        with pytest.raises(SystemExit) as e:
            main(["fit", "car-following", str(tmp_path / "rec.aveas"), "-c", str(cfg), "-o",
                  str(tmp_path / "fit2"), *bad])
        assert e.value.code == 2, (bad, msg)
