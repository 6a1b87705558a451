"""Scenario -> SUMO input files, and the fitting objective (no SUMO needed)."""

from __future__ import annotations

import numpy as np
import pytest
from lxml import etree

from aveas_format.errors import AveasError
from aveas_format.fit import FitConfig, initial_simplex, kde_logpdf, neg_log_likelihood, silverman_bandwidth
from aveas_format.sim import W99_DEFAULTS, Scenario, VehicleClass


def _vtypes(sc: Scenario) -> dict[str, dict[str, str]]:
    root = etree.fromstring(sc.routes_xml("e", "e").encode())
    return {v.get("id"): dict(v.attrib) for v in root.iter("vType")}


def test_w99_vtype_sets_every_cc_parameter():
    vt = _vtypes(Scenario())
    for name in ("car", "truck"):
        a = vt[name]
        assert a["carFollowModel"] == "W99" and a["laneChangeModel"] == "LC2013"
        assert float(a["minGap"]) == W99_DEFAULTS["cc0"]
        for i in range(1, 10):
            assert float(a[f"cc{i}"]) == pytest.approx(W99_DEFAULTS[f"cc{i}"])
        assert float(a["lcKeepRight"]) == 1.0


def test_desired_speed_is_expressed_with_desired_max_speed_and_normc():
    sc = Scenario(classes=[VehicleClass(name="truck", vclass="truck", flow=300, speed_mean_kmh=90,
                                        speed_std_kmh=9)])
    a = _vtypes(sc)["truck"]
    assert float(a["desiredMaxSpeed"]) == pytest.approx(25.0)
    assert a["speedFactor"] == "normc(1,0.1,0.6,1.4)"
    assert float(a["maxSpeed"]) * 3.6 >= 90 + 4.5 * 9 - 1e-6  # above SUMO's 130 km/h truck limit too


def test_cc_overrides_and_alternative_models():
    sc = Scenario().with_cf_params("car", cc1=0.5, cc0=2.0)
    a = _vtypes(sc)["car"]
    assert float(a["cc1"]) == 0.5 and float(a["minGap"]) == 2.0
    with pytest.raises(AveasError, match="unknown W99"):
        Scenario().with_cf_params("car", tau=1.0).routes_xml("e", "e")
    idm = Scenario(classes=[VehicleClass(name="car", flow=100, speed_mean_kmh=120, car_following="IDM",
                                         cf_params={"tau": 1.2, "delta": 4})])
    a = _vtypes(idm)["car"]
    assert a["carFollowModel"] == "IDM" and float(a["tau"]) == 1.2 and "cc1" not in a


def test_common_random_numbers_and_sumo_flows():
    sc = Scenario(duration=600, seed=5)
    root = etree.fromstring(sc.routes_xml("e", "e").encode())
    trips = root.findall("trip")
    n_car = sum(t.get("type") == "car" for t in trips)
    assert 200 < n_car < 360  # 1680/h for 10 min: 280 expected
    departs = [float(t.get("depart")) for t in trips]
    assert departs == sorted(departs) and max(departs) < 600
    # same seed, other mu/sigma: same arrivals, factors 1 + z*sigma/mu from the same z
    sc2 = sc.with_desired_speeds({"car": (120.0, 12.0)})
    t2 = etree.fromstring(sc2.routes_xml("e", "e").encode()).findall("trip")
    assert [t.get("depart") for t in t2] == [t.get("depart") for t in trips]
    f1 = np.array([float(t.get("speedFactor")) for t in trips if t.get("type") == "car"])
    f2 = np.array([float(t.get("speedFactor")) for t in t2 if t.get("type") == "car"])
    np.testing.assert_allclose((f1 - 1) / (15 / 130), (f2 - 1) / (12 / 120), atol=1e-4)
    flows = etree.fromstring(Scenario(random_numbers="sumo").routes_xml("e", "e").encode()).findall("flow")
    assert {f.get("period") for f in flows} == {f"exp({1680 / 3600:.6g})", f"exp({320 / 3600:.6g})"}


def test_scenario_from_toml(tmp_path):
    p = tmp_path / "s.toml"
    p.write_text('duration = 100\nstep_length = 0.25\n[network]\nlanes = 2\n[[classes]]\nname = "car"\n'
                 'flow = 1000\nspeed_mean_kmh = 120\nspeed_std_kmh = 10\ncf_params = { cc1 = 1.1 }\n')
    sc = Scenario.from_toml(p)
    assert sc.network.lanes == 2 and sc.step_length == 0.25 and sc.classes[0].cf_params == {"cc1": 1.1}
    p.write_text("duration = -1\n")
    with pytest.raises(AveasError, match="invalid scenario"):
        Scenario.from_toml(p)


def test_silverman_bandwidth_is_scaled_to_the_data():
    rng = np.random.default_rng(0)
    x = rng.normal(130, 17, 500)
    h = silverman_bandwidth(x)
    assert h == pytest.approx(0.9 * min(x.std(ddof=1), np.subtract(*np.percentile(x, [75, 25])) / 1.34)
                              * 500 ** -0.2)
    assert 4 < h < 6  # km/h, not ~1 as scikit-learn's unscaled "silverman" would be
    assert silverman_bandwidth(x / 3.6) == pytest.approx(h / 3.6)


def test_kde_matches_scipy_and_sklearn():
    from scipy.stats import gaussian_kde

    rng = np.random.default_rng(1)
    s = rng.normal(100, 10, 300)
    pts = np.array([70.0, 100.0, 125.0])
    h = silverman_bandwidth(s)
    ref = gaussian_kde(s, bw_method=h / s.std(ddof=1)).logpdf(pts)
    np.testing.assert_allclose(kde_logpdf(s, pts), ref, rtol=1e-9)
    pytest.importorskip("sklearn")
    np.testing.assert_allclose(kde_logpdf(s, pts, backend="sklearn"), ref, rtol=1e-6)


def test_neg_log_likelihood_prefers_the_true_distribution():
    rng = np.random.default_rng(2)
    rec = {"car": rng.normal(130, 17, 178), "truck": rng.normal(89, 6, 33)}
    good = {"car": rng.normal(130, 17, 2000), "truck": rng.normal(89, 6, 400)}
    bad = {"car": rng.normal(120, 17, 2000), "truck": rng.normal(89, 12, 400)}
    assert neg_log_likelihood(rec, good) < neg_log_likelihood(rec, bad)
    assert np.isfinite(neg_log_likelihood(rec, {"car": np.array([0.0]), "truck": np.empty(0)}))


def test_starts_and_simplex_stay_in_bounds():
    cfg = FitConfig(restarts=50)
    b = cfg.bounds_array()
    rec = {"car": np.array([120.0, 130.0, 140.0]), "truck": np.array([85.0, 95.0])}
    st = cfg.starts_array(rec)
    assert st.shape == (50, 4) and np.all(st >= b[:, 0]) and np.all(st <= b[:, 1])
    # the first restart starts from the data: the recorded values' mean and standard deviation
    np.testing.assert_allclose(st[0], [130.0, 10.0, 90.0, np.sqrt(50.0)])
    assert FitConfig(restarts=3, starts="uniform").starts_array(rec)[0][0] != 130.0
    assert FitConfig(start={"mu_car": 150.0}).starts_array(rec)[0][0] == 150.0
    for x0 in st:
        simplex = initial_simplex(x0, b, 0.2)
        assert simplex.shape == (5, 4)
        assert np.all(simplex >= b[:, 0]) and np.all(simplex <= b[:, 1])
