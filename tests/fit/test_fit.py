"""The fitter: parameter recovery (fast and slow), resuming, Dask, CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers_sim import NARROW, PAPER, cli_simulated_recording, small_scenario

from aveas_format.fit import FitConfig, fit_desired_speed, load_runs
from aveas_format.sim import simulate


def synthetic_recorded(n_car: int = 178, n_truck: int = 33, seed: int = 7, **kw) -> dict[str, np.ndarray]:
    """'Recorded' per-vehicle mean speeds: a run at the paper's parameters with another seed,
    subsampled to the paper's counts."""
    ms = simulate(small_scenario(seed=seed, **kw), fcd=False).mean_speeds()
    rng = np.random.default_rng(seed)
    return {"car": rng.choice(ms["car"], n_car, replace=False),
            "truck": rng.choice(ms["truck"], n_truck, replace=False)}


def _check(best: dict, tol_mu: float, tol_sigma: float) -> None:
    for c in ("car", "truck"):
        assert abs(best[f"mu_{c}"] - PAPER[c][0]) < tol_mu, best
        assert abs(best[f"sigma_{c}"] - PAPER[c][1]) < tol_sigma, best


def test_fast_parameter_recovery(sumo, tmp_path):
    """Small variant (the paper's experiment is test_full_parameter_recovery, slow): 178 cars and
    33 trucks 'recorded' in 10 min on a 1 km road, fitted back with 2 CMA-ES restarts (in 2
    processes) of one generation each on 5 min of demand, then one round of the response surface
    and one under a second seed: mu within 4 km/h, sigma within 5 km/h (measured: 1.7 and 0.6 at
    most), and best.json says whether the fit converged, why it stopped, and the standard errors
    with their simulation-seed and bootstrap parts."""
    recorded = synthetic_recorded(duration=600)
    cfg = FitConfig(scenario=small_scenario(duration=300, lane_change_duration=0), bounds=NARROW,
                    restarts=2, maxfev=8, seed=3, refine_rounds=1, refine_seeds=2, bootstrap=6)
    res = fit_desired_speed(recorded, cfg, workers=2, outdir=tmp_path / "fit")
    assert len(res.runs) == 2 and not res.failed
    best = json.loads((tmp_path / "fit" / "best.json").read_text())
    for n in cfg.names:  # bounds respected
        assert cfg.bounds[n][0] <= best[n] <= cfg.bounds[n][1]
    _check(best, tol_mu=4.0, tol_sigma=5.0)
    assert best["estimate"] == "response surface" and best["method"] == "cma"
    assert isinstance(best["converged"], bool) and best["stop"]
    # converged only where the best restart converged by its optimiser's own criterion (at most
    # 8 evaluations: CMA-ES stops at the cap here) and the surface resolved its minimum
    b = best["best_restart"]
    assert best["optimiser_converged"] == b["converged"]
    assert best["converged"] == (b["converged"] and best["surface_converged"])
    assert best["stop"].startswith(f"the best restart ({b['restart']}) "
                                   + ("converged" if b["converged"] else "did not converge: evaluation cap (8)"))
    assert best["evaluations"] == sum(r["nfev"] for r in res.runs) + 50  # 2 designs of 25
    assert all(0 < best["se"][n] < 10 for n in cfg.names), best["se"]
    rs = best["response_surface"]
    assert rs["seeds"] == 2 and len(rs["seed_minima"]) == 2
    assert rs["bootstrap"] == 6 and set(rs["bootstrap_bias"]) == set(cfg.names)
    assert best["se_sampling"] != best["se_information"]  # the bootstrap's, not the curvature's
    for n in cfg.names:  # the seed's part adds to the sampling part
        assert best["se_seed"][n] > 0
        assert best["se"][n] ** 2 == pytest.approx(best["se_sampling"][n] ** 2 + best["se_seed"][n] ** 2,
                                                   rel=1e-4)
        assert min(m[n] for m in rs["seed_minima"]) <= best[n] <= max(m[n] for m in rs["seed_minima"])
    for n in cfg.names:
        lo, hi = best["ci95"][n]
        assert lo < best[n] < hi
    for r in res.runs:  # every restart says whether it converged and why it stopped
        assert isinstance(r["converged"], bool) and r["stop"] and r["nfev"] <= 9
    for f in ("runs.parquet", "best.json", "fit_histogram.png", "fit_parameters.png"):
        assert (tmp_path / "fit" / f).exists()


def test_a_fit_stopped_at_the_cap_says_so(sumo, tmp_path):
    """The paper's Nelder-Mead with a small evaluation cap: the restart and the fit report that
    they stopped at the cap, in the result and in best.json."""
    recorded = synthetic_recorded(n_car=40, n_truck=10, duration=300, length=400, inflow=100)
    cfg = FitConfig(scenario=small_scenario(duration=120, length=400, inflow=100), bounds=NARROW,
                    method="nelder-mead", starts="uniform", restarts=1, maxfev=6, refine=False)
    res = fit_desired_speed(recorded, cfg, outdir=tmp_path / "fit", figures=False)
    best = json.loads((tmp_path / "fit" / "best.json").read_text())
    assert not res.converged and best["converged"] is False
    assert best["stop"].startswith("the best restart (0) did not converge: evaluation cap (6)")
    assert best["estimate"] == "best restart" and best["surface_converged"] is None
    assert best["restarts_at_cap"] == 1 and "se" not in best


def test_resume_skips_stored_restarts(sumo, tmp_path):
    recorded = synthetic_recorded(n_car=40, n_truck=10, duration=300, length=400, inflow=100)
    cfg = FitConfig(scenario=small_scenario(duration=120, length=400, inflow=100), bounds=NARROW,
                    restarts=1, maxfev=6, refine=False)
    res = fit_desired_speed(recorded, cfg, outdir=tmp_path / "fit", figures=False)
    assert len(res.runs) == 1
    res2 = fit_desired_speed(recorded, cfg.model_copy(update={"restarts": 2}), outdir=tmp_path / "fit",
                             figures=False)
    assert [r["restart"] for r in res2.runs] == [0, 1]
    assert res2.runs[0] == res.runs[0]  # not run again
    assert len(load_runs(tmp_path / "fit")) == 2
    with pytest.raises(Exception, match="different configuration"):
        fit_desired_speed(recorded, cfg.model_copy(update={"maxfev": 7}), outdir=tmp_path / "fit")


def test_restarts_on_a_dask_local_cluster(sumo, tmp_path):
    distributed = pytest.importorskip("distributed")
    recorded = synthetic_recorded(n_car=40, n_truck=10, duration=300, length=400, inflow=100)
    cfg = FitConfig(scenario=small_scenario(duration=120, length=400, inflow=100), bounds=NARROW,
                    restarts=2, maxfev=6, refine=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster:
        res = fit_desired_speed(recorded, cfg, scheduler=cluster.scheduler_address, figures=False)
    assert sorted(r["restart"] for r in res.runs) == [0, 1] and not res.failed


def test_cli_fit_desired_speed(sumo, tmp_path, capsys):
    from aveas_format.cli import main

    cfg, _ = cli_simulated_recording(tmp_path, 'duration = 120\nseed = 5\n[network]\nlength = 400\n'
                                                'inflow = 100\n')
    capsys.readouterr()
    with pytest.raises(SystemExit) as e:
        main(["fit", "desired-speed", str(tmp_path / "rec.aveas"), "-c", str(cfg), "-o",
              str(tmp_path / "fit"), "-r", "1", "--maxfev", "6", "--s-range", "100,500",
              "--no-refine", "--method", "nelder-mead",
              "--bounds", json.dumps({k: list(v) for k, v in NARROW.items()})])
    assert e.value.code == 0
    best = json.loads((tmp_path / "fit" / "best.json").read_text())
    assert set(best) >= {"mu_car", "sigma_car", "mu_truck", "sigma_truck", "fun", "converged", "stop"}
    # the verdict and the restart's own message agree (6 evaluations: the cap)
    err = capsys.readouterr().err
    assert best["converged"] is False and best["optimiser_converged"] is False
    assert "the fit did not converge: the best restart (0) did not converge: evaluation cap (6)" in err
    assert "restart 0 did not converge: evaluation cap (6)" in err and "converged: true" not in err
    # without --config: the simulation the recording describes (its 120 s of demand, its section)
    with pytest.raises(SystemExit) as e:
        main(["fit", "desired-speed", str(tmp_path / "rec.aveas"), "-o", str(tmp_path / "fit-rec"),
              "-r", "1", "--maxfev", "5", "--s-range", "100,500", "--no-refine", "--method",
              "nelder-mead", "--bounds", json.dumps({k: list(v) for k, v in NARROW.items()})])
    assert e.value.code == 0
    err = capsys.readouterr().err
    used = json.loads((tmp_path / "fit-rec" / "config.json").read_text())["scenario"]
    assert "simulating what the recordings show:" in err and "a 400 m section" in err
    assert 90 < used["duration"] <= 125 and used["network"]["length"] == 400.0
    assert used["lane_change_duration"] == 0.0 and {c["name"] for c in used["classes"]} <= {"car", "truck"}
    with pytest.raises(SystemExit) as e:
        main(["fit", "desired-speed", str(tmp_path / "rec.aveas"), "-c", str(cfg), "-o",
              str(tmp_path / "fit2"), "--method", "powell"])
    assert e.value.code == 2


@pytest.mark.slow
def test_full_parameter_recovery(sumo, tmp_path):
    """The paper's experiment with the default fitter: 178 cars and 33 trucks 'recorded' at the
    paper's parameters on the paper's road (1.5 km inflow + 4 km, 15 min of demand), fitted back
    with 4 CMA-ES restarts and the response surface on all cores; every parameter within 2.5
    standard errors of the truth (the recovery study measures bias and RMSE over seeds)."""
    from aveas_format.fit.study import paper_scenario

    ms = simulate(paper_scenario().model_copy(update={"seed": 7}), fcd=False).mean_speeds()
    rng = np.random.default_rng(7)
    recorded = {"car": rng.choice(ms["car"], 178, replace=False),
                "truck": rng.choice(ms["truck"], 33, replace=False)}
    cfg = FitConfig(scenario=paper_scenario().model_copy(update={"seed": 1007}), seed=1)
    res = fit_desired_speed(recorded, cfg, workers=None, outdir=tmp_path / "fit")
    assert not res.failed
    best = json.loads((tmp_path / "fit" / "best.json").read_text())
    assert best["surface_converged"], best["stop"]
    # the flag and the restarts agree: converged only where the best restart converged by its
    # optimiser's criterion (not at the cap of 200 evaluations)
    b = best["best_restart"]
    assert best["converged"] == (b["converged"] and best["surface_converged"]), best["stop"]
    assert best["stop"].startswith(f"the best restart ({b['restart']}) "
                                   + ("converged" if b["converged"] else "did not converge"))
    for c in ("car", "truck"):
        for k, truth in zip(("mu", "sigma"), PAPER[c], strict=True):
            n = f"{k}_{c}"
            assert abs(best[n] - truth) < 2.5 * best["se"][n], (n, best[n], best["se"][n])
