"""Our surrogate measures against SUMO's own SSM device on the same traffic, sample by sample
(docs/derive.md "Checked against SUMO's SSM device"). Skipped without SUMO."""

from __future__ import annotations

import pandas as pd
import pytest

from aveas_format.derive import derive
from aveas_format.sim.ssm import (
    autobahn_scenario,
    compare,
    compare_episodes,
    junction_scenario,
    read_ssm,
    ssm_args,
)


def test_ssm_args_log_every_measure():
    a = ssm_args("x.xml")
    assert a[a.index("--device.ssm.measures") + 1].split() == ["TTC", "DRAC", "MDRAC", "PET",
                                                               "PPET", "BR", "SGAP", "TGAP"]
    assert a[a.index("--precision") + 1] == "6"


def test_junction_followers_and_straight_crossings_agree(sumo, tmp_path):
    """A 4-way priority junction, 90 s at 0.1 s, drivers without random imperfection (sigma 0:
    SUMO's device and its FCD then see the same acceleration): lane-follower TTC, DRAC and MDRAC
    on one lane agree with SUMO's sample by sample (within 1 % or the outputs' 6-decimal
    rounding: all DRAC, all TTC up to 1000 s; median error ~1e-7), SGAP/TGAP with our gap/thw;
    at right-angle crossings the crossing DRAC, PPET and PET equal SUMO's; every crossing SUMO
    logs is found where both vehicles passed it in the recording and SUMO's lanes cross
    (docs/derive.md "Checked against SUMO's SSM device")."""
    run = junction_scenario(tmp_path / "j", duration=90.0, seed=1, sigma=0.0)
    assert (tmp_path / "j" / "ssm.xml").exists()
    rec = run.recording
    derive(rec, only=["interactions", "conflicts"], velocities="states")
    c = compare(run)
    for m in ("ttc", "drac", "mdrac"):
        assert c[m]["same_lane_both_finite"] >= 1000, c
        assert c[m]["same_lane_median_rel"] < 1e-4, (m, c[m])
    assert c["ttc"]["same_lane_within"] >= 0.97, c["ttc"]
    # the rest on one lane: TTCs of 10^4-10^5 s (closing speeds of 10^-5 m/s, rounded in the FCD)
    assert c["ttc"]["same_lane_below_resolved_within"] >= 0.999, c["ttc"]
    assert c["drac"]["same_lane_within"] >= 0.99, c["drac"]
    # SUMO's SGAP and TGAP are our leader rows' gap and thw: all of them where the vehicle and
    # our leader are on one lane outside the junction (TGAP: up to 1000 s, above which the FCD's
    # 6-decimal speeds of a stopped vehicle round it); the rest is another leader in or beyond
    # the junction (docs/derive.md)
    for m in ("sgap", "tgap"):
        assert c[m]["both_finite"] >= 1000 and c[m]["within"] >= 0.85, (m, c[m])
        assert c[m]["median_rel"] < 1e-4, (m, c[m])
        assert c[m]["one_lane_both_finite"] >= 0.7 * c[m]["both_finite"], (m, c[m])
    assert c["sgap"]["one_lane_within"] >= 0.999, c["sgap"]
    assert c["tgap"]["one_lane_resolved_within"] >= 0.999, c["tgap"]
    # PET of straight-on crossings (routes W->E / E->W against S->N / N->S) at the crossing
    # point of the paths (derived/conflicts)
    x = c["crossing"]
    assert x["pet_straight"]["matched"] >= 1, x
    assert x["pet_straight"]["max_abs_s"] < 1e-3, x
    assert x["matched"] >= 100, x
    for m in ("drac", "ppet"):
        assert x[f"straight_{m}"]["both_finite"] >= 10, x
        assert x[f"straight_{m}"]["within"] >= 0.99, (m, x[f"straight_{m}"])
    # turning: SUMO's lane-level conflict area differs by design (its entry 0.5-3 m earlier)
    assert 0.0 < x["turning_ppet"]["median_rel"] < 0.2, x["turning_ppet"]
    # the rest of SUMO's crossing pairs: a vehicle still queued at the end of the run (SUMO
    # knows its route, the recording not its path) or opposing left turns (SUMO's lanes do not
    # cross)
    assert x["pairs"]["missed"] == [] and x["pairs"]["found"] >= 15, x["pairs"]
    # SUMO's samples of the pairs found have a row here at the same step, except the steps at
    # which one of the two would stop before the conflict area (no row: it never enters)
    assert x["pairs"]["found_samples_matched"] >= 0.97 * x["pairs"]["found_samples"], x["pairs"]
    # conflict by conflict: every crossing conflict episode of SUMO's (TTC <= 3 s or PPET or PET
    # <= 2 s) that both can see is one of ours too; the others are opposing left turns (SUMO's
    # lanes do not cross: its values are not measurements) or a vehicle whose way to the
    # crossing the recording does not hold (docs/derive.md)
    ep = compare_episodes(run)
    comparable = ep["by_class"]["comparable"]
    assert comparable >= 4 and ep["comparable_matched"] >= 0.95 * comparable, ep["by_class"]
    assert ep["sumo_episodes"] == sum(ep["by_class"].values())
    for key in ("straight_min_ttc", "straight_pet"):
        if ep[f"{key}_n"]:
            assert ep[f"{key}_max_abs_s"] <= 0.2, ep


@pytest.mark.slow
def test_autobahn_followers_agree(sumo, tmp_path):
    """The paper's autobahn (3 lanes, cars and trucks, W99, 0.5-s steps), 10 min: lane-follower
    TTC on one lane within 1 % of SUMO's for >= 95 % of the samples (median ~1e-8); the rest are
    lane changes (our speed is along the vehicle's heading, SUMO's along its lane)."""
    run = autobahn_scenario(tmp_path / "a", duration=600.0)
    derive(run.recording, only=["interactions"], velocities="states")
    c = compare(run)
    assert c["ttc"]["same_lane_both_finite"] >= 5000
    assert c["ttc"]["same_lane_within"] >= 0.95 and c["ttc"]["same_lane_median_rel"] < 1e-6
    assert c["drac"]["same_lane_within"] >= 0.90


def test_read_ssm_tables(sumo, tmp_path):
    run = junction_scenario(tmp_path / "j", duration=30.0, seed=2)
    s = read_ssm(tmp_path / "j" / "ssm.xml")
    e = s["encounters"].to_pandas()
    assert {"ego", "foe", "time", "type", "ttc", "drac", "mdrac", "ppet"} <= set(e.columns)
    assert (e.type >= 0).all() and len(s["globals"]) > 0
    g = s["globals"].to_pandas()
    assert (g.br.dropna() >= 0).all()
    assert isinstance(run.recording.states.num_rows, int)
    pd.testing.assert_frame_equal(e, run.ssm["encounters"].to_pandas())
