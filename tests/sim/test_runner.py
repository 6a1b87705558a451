"""The SUMO runner: valid recordings, desired speeds, errors, CLI, sensitivity."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers_sim import PAPER, small_scenario

import aveas_format
from aveas_format.sim import SimulationError, SumoNotFoundError, find_sumo, simulate


def test_run_produces_a_valid_recording_on_the_same_map(sumo, tmp_path):
    res = simulate(small_scenario(duration=120), recording=True)
    rec = res.recording
    assert rec.participants.num_rows > 40
    assert set(rec.participants["class"].to_pylist()) == {"car", "truck"}
    assert rec.meta.provenance == "simulated"
    report = aveas_format.validate(rec)
    assert report.counts["error"] == 0, [f.message for f in report.findings[:5]]
    # on the map: every sample has road coordinates, lanes -1..-3
    lanes = set(rec.states["lane_id"].to_pylist())
    assert None not in lanes and lanes <= {-1, -2, -3}
    # trucks never on the left lane (OpenDRIVE -1, next to the centre line; SUMO index 2)
    pid_truck = {p for p, c in zip(rec.participants["participant_id"].to_pylist(),
                                   rec.participants["class"].to_pylist(), strict=True) if c == "truck"}
    lane_of_trucks = {ln for p, ln in zip(rec.states["participant_id"].to_pylist(),
                                          rec.states["lane_id"].to_pylist(), strict=True) if p in pid_truck}
    assert -1 not in lane_of_trucks
    path = rec.write(tmp_path / "sim.aveas")
    assert aveas_format.validate(path).counts["error"] == 0
    # mean speeds from the FCD agree with those from the recording on the measurement section
    from aveas_format.fit import recorded_mean_speeds

    ms = res.mean_speeds()
    mr = recorded_mean_speeds(rec, road_id=rec.states["road_id"][0].as_py(), s_range=(300.0, 1300.0))
    for c in ("car", "truck"):
        assert len(ms[c]) == len(mr[c]) and len(ms[c]) > 5
        assert abs(ms[c].mean() - mr[c].mean()) < 0.5


@pytest.mark.parametrize("mode", ["common", "sumo"])
def test_desired_speeds_follow_the_normal_distribution(sumo, mode):
    sc = small_scenario(duration=1800, length=200, inflow=100, random_numbers=mode)
    res = simulate(sc, speed_factors=True)
    for c in ("car", "truck"):
        mu, sigma = PAPER[c]
        desired = np.array([f for v, f in res.speed_factors.items() if v.startswith(c)]) * mu
        n = len(desired)
        assert n > 100
        assert abs(desired.mean() - mu) < 3.5 * sigma / np.sqrt(n) + 0.3
        assert abs(desired.std(ddof=1) - sigma) < 0.15 * sigma
    # and the vehicles reach them on an empty-ish road: mean of simulated mean speeds near mu
    ms = res.mean_speeds()
    assert abs(ms["truck"].mean() - PAPER["truck"][0]) < 3.0
    assert abs(ms["car"].mean() - PAPER["car"][0]) < 8.0


def test_missing_sumo_is_a_clear_error(monkeypatch, tmp_path):
    import sys

    from aveas_format.sim import runner

    find_sumo.cache_clear()
    monkeypatch.setenv("SUMO_HOME", str(tmp_path))
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setitem(sys.modules, "sumo", None)
    try:
        with pytest.raises(SumoNotFoundError, match=r'pip install "aveas-format\[sim\]"'):
            runner.simulate(small_scenario())
    finally:
        find_sumo.cache_clear()


def test_a_failed_run_reports_its_log(sumo):
    with pytest.raises(SimulationError, match="sumo failed.*log tail"):
        simulate(small_scenario(duration=10, extra_args=["--no-such-option", "1"]))


def test_cli_sim_run_and_sensitivity(sumo, tmp_path):
    from aveas_format.cli import main

    cfg = tmp_path / "s.toml"
    cfg.write_text('duration = 60\nseed = 2\n[network]\nlength = 500\ninflow = 100\n')
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "--config", str(cfg), "-o", str(tmp_path / "sim.aveas"), "-O",
              "license=CC0-1.0"])
    assert e.value.code == 0
    sim = aveas_format.open(tmp_path / "sim.aveas")
    assert sim.participants.num_rows > 10
    assert (sim.meta.rights.license, sim.meta.acquisition.partner) == ("CC0-1.0", "aveas-format sim")
    stand_ins = {"metadata.rights_unclear", "metadata.partner_placeholder", "metadata.start_time_implausible"}
    assert not aveas_format.validate(sim).codes() & stand_ins
    with pytest.raises(SystemExit) as e:
        main(["sim", "sensitivity", "--config", str(cfg), "-o", str(tmp_path / "sens"), "-p", "cc1",
              "-n", "2", "--min-ttc-samples", "2"])
    assert e.value.code == 0
    rows = json.loads((tmp_path / "sens" / "sensitivity.json").read_text())
    assert [r["value"] for r in rows] == [0.1, 1.0]
    assert all(r["min_ttc"] > 0 and r["min_mean_ttc"] >= r["min_ttc"] for r in rows)
    assert all(r["n_vehicles_mean"] >= 1 for r in rows)
    assert (tmp_path / "sens" / "sensitivity.png").stat().st_size > 1000


def test_ttc_summary_needs_enough_samples_per_vehicle():
    """A vehicle with a single short TTC sample no longer decides the minimum mean TTC alone."""
    import numpy as np

    from aveas_format.sim.sensitivity import ttc_summary

    pid = np.array([1, 2, 2, 2, 3, 3])
    ttc = np.array([4.0, 9.0, 11.0, 10.0, 6.0, 8.0])
    every = ttc_summary(pid, ttc)
    assert every["min_ttc"] == 4.0 and every["min_mean_ttc"] == 4.0 and every["n_vehicles_mean"] == 3
    two = ttc_summary(pid, ttc, min_samples=2)
    assert two["min_ttc"] == 4.0 and two["min_mean_ttc"] == 7.0 and two["n_vehicles_mean"] == 2
    none = ttc_summary(pid, ttc, min_samples=4)
    assert np.isnan(none["min_mean_ttc"]) and none["n_vehicles_mean"] == 0
    assert np.isnan(ttc_summary(pid[:0], ttc[:0])["min_ttc"])


def test_network_from_a_map_file(sumo, tmp_path):
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sim import Network

    xodr = tmp_path / "road.xodr"
    xodr.write_text(straight_highway(length=800, lanes_right=2, lanes_left=2,
                                     geo_reference="+proj=tmerc +lat_0=49 +lon_0=8 +ellps=WGS84 +units=m"))
    sc = small_scenario(duration=60).model_copy(update={"network": Network(map=xodr)})
    from aveas_format.errors import AveasError

    with pytest.raises(AveasError, match="from_edge"):  # two directions: two source edges
        simulate(sc)
    sc.network.from_edge = sc.network.to_edge = "-1"
    res = simulate(sc, recording=True)
    assert res.recording.map_source == xodr.read_bytes()
    assert len(res.mean_speeds()["car"]) > 10  # whole edge measured
    assert aveas_format.validate(res.recording).counts["error"] == 0


def test_section_crossings_give_the_fcd_mean_speeds(sumo):
    """Without FCD SUMO writes only the crossings of the measurement section's ends; the mean speed
    (section length / time between them) is the FCD's mean speed over the section, vehicle by
    vehicle (the same time mean, to the FCD's 0.5 s sampling of a 1 km section), with lane changes
    taking time or not."""
    from aveas_format.sim import prepare_network

    for lcd in (0.0, 3.0):
        sc = small_scenario(duration=300, lane_change_duration=lcd)
        net = prepare_network(sc.network)
        full = simulate(sc, network=net)
        lean = simulate(sc, network=net, fcd=False)
        assert lean.fcd is None and lean.section.num_rows > 80
        assert set(lean.timings) >= {"network", "routes", "sumo", "read"}
        a, b = full.mean_speeds(), lean.mean_speeds()
        for c in ("car", "truck"):
            assert len(a[c]) == len(b[c]) > 5
            np.testing.assert_allclose(np.sort(a[c]), np.sort(b[c]), atol=0.5)
            assert abs(a[c].mean() - b[c].mean()) < 0.05
    with pytest.raises(ValueError, match="needs the FCD"):
        simulate(sc, fcd=False, recording=True)


def test_a_measurement_section_of_several_edges_falls_back_to_the_fcd_of_those_edges(sumo, tmp_path):
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sim import Network

    xodr = tmp_path / "road.xodr"
    xodr.write_text(straight_highway(length=600, lanes_right=2, lanes_left=2,
                                     geo_reference="+proj=tmerc +lat_0=49 +lon_0=8 +ellps=WGS84 +units=m"))
    sc = small_scenario(duration=60).model_copy(update={"network": Network(
        map=xodr, from_edge="-1", to_edge="-1", measure_edges=["-1"])})
    res = simulate(sc, fcd=False)
    assert res.section is None and res.fcd.num_rows > 0  # no position range: the edges' FCD
    assert set(res.fcd["edge"].to_pylist()) == {"-1"}
    assert len(res.mean_speeds()["car"]) > 5


def test_stratified_desired_speeds_have_no_sampling_error(sumo):
    """speed_sampling = "stratified": the standard-normal draws are the normal's quantiles, so the
    desired speeds' sample mean is mu and their spread sigma (to the discreteness of n quantiles);
    the arrival times are those of the random draws, and changing mu/sigma keeps the draws."""
    sc = small_scenario(duration=1800, length=200, inflow=100)
    strat = sc.model_copy(update={"speed_sampling": "stratified"})
    for (t_r, z_r), (t_s, z_s) in zip(sc.draws(), strat.draws(), strict=True):
        np.testing.assert_array_equal(t_r, t_s)
        assert abs(z_s.mean()) < 1e-9 and abs(z_s.std() - 1) < 0.01
        assert abs(z_r.mean()) > 1e-6
    res = simulate(strat, speed_factors=True, fcd=False)
    for c in ("car", "truck"):
        mu, sigma = PAPER[c]
        desired = np.array([f for v, f in res.speed_factors.items() if v.startswith(c)]) * mu
        assert abs(desired.mean() - mu) < 0.01 and abs(desired.std() - sigma) < 0.01 * sigma
    other = strat.with_desired_speeds({"car": (120.0, 10.0)})
    np.testing.assert_array_equal(other.draws()[0][1], strat.draws()[0][1])  # common random numbers
    from aveas_format.sim import Scenario

    with pytest.raises(ValueError, match="needs random_numbers"):
        Scenario(random_numbers="sumo", speed_sampling="stratified")
