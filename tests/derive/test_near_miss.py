"""Critical events against scenes with known truth (aveas_format.sample.scenes; docs/derive.md
"Events" and "Against the truth"): none in lane-keeping traffic whatever the declared noise, every
true conflict found with its minimum TTC within max(0.3 s, 20 %) of the truth, the TTC's std
calibrated, the collision probability against an independent simulation of the truth; the
evidence, persistence and encounter rules on hand-made rows. The benchmark
(benchmarks/bench_near_miss.py) runs the same on an hour of traffic and many more conflicts."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.derive import derive
from aveas_format.derive.events import EventsParams
from aveas_format.derive.events._episodes import encounters, threshold_episodes, ttc_probability
from aveas_format.sample.scenes import close_pass_scene, conflict_scene, traffic_scene
from aveas_format.sample.truth import truth_collides

#: the columns derived/kinematics gained for the criticality (issue 40)
NEW_KINEMATICS = ("x", "x_std", "y", "y_std", "xy_corr", "vx", "vx_std", "vy", "vy_std",
                  "vxvy_corr")


def critical(rec) -> list[dict]:
    ev = rec.events
    return [] if ev is None else [e for e in ev.to_pylist() if e["origin"] == "derived"
                                  and e["kind"] in ("conflict", "near_miss")]


def test_lane_keeping_traffic_has_no_critical_event():
    """90 s of three-lane traffic (net headways >= 1.8 s) with the worst aerial noise (0.3 m,
    velocities 0.6 m/s): no conflict, no near miss. Derived as before issue 40 (the measured
    across-motion velocity extrapolated, every sample below the threshold an event) the same
    recording has dozens — lateral noise pointing at a neighbour."""
    rec = traffic_scene(90.0, method="aerial", position_std=0.3, seed=11)
    derive(rec)
    assert critical(rec) == []
    k = rec.derived["kinematics"]
    rec.derived["kinematics"] = k.drop_columns(list(NEW_KINEMATICS))
    derive(rec, only=["interactions", "events"], evidence=0.5, persistence_s=0.0,
           collision_samples=0, encounter_gap_s=0.0)
    assert len(critical(rec)) >= 10


@pytest.mark.parametrize("method,std", [("aerial", 0.3), ("lidar", 0.2)])
@pytest.mark.parametrize("kind,ttc", [("cut_in", 0.8), ("hard_braking", 1.6), ("crossing", 1.2),
                                      ("pedestrian", 1.0)])
def test_true_conflicts_are_found(kind, ttc, method, std):
    """Each planted conflict is one event (kind conflict: the recorded braking averted it) of
    its pair with its minimum TTC within max(0.3 s, 20 %) of the truth, and nothing else in the
    scene is critical (its lane-keeping neighbours)."""
    rec, truth = conflict_scene(kind, ttc, method=method, position_std=std, seed=3,
                                return_truth=True)
    c = truth["conflicts"][0]
    assert c["min_ttc"] == pytest.approx(ttc, abs=1e-6)  # the design
    derive(rec)
    ev = critical(rec)
    assert [set(e["participant_ids"]) for e in ev] == [set(c["participants"])], ev
    e = ev[0]
    assert e["metric"] == "ttc" and abs(e["value"] - ttc) <= max(0.3, 0.2 * ttc), e
    assert e["value_std"] > 0 and e["duration"] >= 0.3
    assert e["kind"] == "conflict" and e["collision_probability"] < 0.5
    attrs = json.loads(e["attributes"])
    assert attrs["collision_probability"]["ci95"][0] <= e["collision_probability"]


def test_the_ttc_std_covers_the_truth():
    """Sample by sample against the same scenes without noise: |TTC - truth| <= reported std on
    55-80 % of the conflicts' samples with a true TTC up to 3 s."""
    inside = total = 0
    for kind, ttc, method, std in (("cut_in", 1.2, "aerial", 0.2), ("crossing", 0.8, "lidar", 0.1),
                                   ("pedestrian", 1.4, "aerial", 0.3),
                                   ("hard_braking", 1.0, "lidar", 0.2)):
        rec, truth = conflict_scene(kind, ttc, method=method, position_std=std, seed=5,
                                    return_truth=True)
        exact = conflict_scene(kind, ttc, method=method, position_std=0.0, seed=5)
        derive(rec, only=["interactions"])
        derive(exact, only=["interactions"])
        a, b = truth["conflicts"][0]["participants"]
        rows = []
        for r in (rec, exact):
            it = r.derived["interactions"]
            it = it.filter(pc.and_(pc.equal(it["participant_id"], a), pc.equal(it["other_id"], b)))
            rows.append(it.to_pandas().set_index(["time", "relation"]))
        j = rows[0].join(rows[1].add_suffix("_true"), how="inner")
        j = j[np.isfinite(j.ttc) & np.isfinite(j.ttc_true) & np.isfinite(j.ttc_std)
              & (j.ttc_true <= 3.0)]
        inside += int((np.abs(j.ttc - j.ttc_true) <= j.ttc_std).sum())
        total += len(j)
    assert total >= 100
    assert 0.55 <= inside / total <= 0.80, (inside, total)


def test_collision_probability_against_the_truth():
    """Two vehicles crossing paths at constant speed, the second passing behind the first with a
    true clearance from a collision (-0.3 m) to 1.5 m: the derived probability falls with the
    clearance and matches the probability of the true encounter's variations (an independent
    simulation: shapely footprints on a 100 Hz grid) within 0.2."""
    rng = np.random.default_rng(0)
    got = []
    for k, margin in enumerate((-0.3, 0.0, 0.2, 0.5, 1.5)):
        rec, truth = close_pass_scene(margin, method="aerial", position_std=0.2, seed=k,
                                      return_truth=True)
        derive(rec)
        ev = critical(rec)
        assert len(ev) == 1, ev
        p_true = truth_collides(rec, truth, ev[0], rng, draws=60)
        got.append((margin, ev[0]["collision_probability"], p_true))
    p = [g[1] for g in got]
    assert p[0] >= 0.9 and p[-1] <= 0.02 and all(a >= b - 0.05 for a, b in zip(p, p[1:])), got
    assert all(abs(a - b) <= 0.2 for _, a, b in got), got
    # a recorded collision is a near miss by the paper's definition only in name: the event says
    # so by its probability (kind near_miss from 0.5)
    assert ev[0]["kind"] == "conflict"


# --- the rules on hand-made rows -------------------------------------------------------------------

def _rows(ttc, step=0.04, kind="lane_1d", gap=None, closing=None, gap_std=0.1, cl_std=0.1):
    n = len(ttc)
    ttc = np.asarray(ttc, float)
    closing = np.full(n, 5.0) if closing is None else np.asarray(closing, float)
    gap = ttc * closing if gap is None else np.asarray(gap, float)
    nan = np.full(n, np.nan)
    return {"rel": np.full(n, "leader", object), "pid": np.zeros(n, np.int64),
            "oid": np.ones(n, np.int64), "kind": np.full(n, kind, object),
            "time": np.arange(n) * step, "ttc": ttc, "ttc_std": np.full(n, 0.05), "gap": gap,
            "gap_std": np.full(n, gap_std), "closing_speed": closing,
            "closing_speed_std": np.full(n, cl_std), "drac": nan, "drac_std": nan, "mdrac": nan,
            "mdrac_std": nan, "psd": nan, "psd_std": nan}


def test_one_frame_dips_do_not_count():
    """A TTC below the threshold for one frame (or for less than ``persistence_s``) is no
    episode; for 0.3 s it is, at 25 Hz and at 10 Hz alike."""
    p = EventsParams()
    for step in (0.04, 0.1):
        n = int(round(3.0 / step))
        for length_s, want in ((step, 0), (0.2, 0), (0.32, 1), (1.0, 1)):
            ttc = np.full(n, 8.0)
            k = max(int(round(length_s / step)), 1)
            ttc[10:10 + k] = 1.0
            r = _rows(ttc, step)
            rows = np.flatnonzero(ttc <= 3.0)
            prob = np.full(n, np.nan)
            prob[rows] = ttc_probability(r, rows, 3.0, None)
            got = threshold_episodes(r, "ttc", 3.0, prob, p, step)
            assert len(got) == want, (step, length_s, got)


def test_the_evidence_is_the_probability_below_the_threshold():
    """Along the lane P(TTC <= thr) = P(gap - thr closing <= 0): the closed form against Monte
    Carlo draws of a Gaussian gap and closing speed; a TTC just below the threshold with a large
    std is not critical at the default evidence (0.9), one well below is."""
    rng = np.random.default_rng(1)
    g, dv, sg, sv, thr = 9.0, 3.5, 0.8, 0.6, 3.0
    r = _rows([g / dv], gap=[g], closing=[dv], gap_std=sg, cl_std=sv)
    p = ttc_probability(r, np.array([0]), thr, None)[0]
    G, V = rng.normal(g, sg, 400_000), rng.normal(dv, sv, 400_000)
    mc = np.mean((V > 0) & (G / V <= thr) | (G <= 0))
    assert p == pytest.approx(mc, abs=0.003)
    par = EventsParams()
    far = _rows(np.full(20, 2.9), gap_std=1.0, cl_std=1.0)
    near = _rows(np.full(20, 1.0))
    for r, want in ((far, 0), (near, 1)):
        rows = np.arange(20)
        prob = ttc_probability(r, rows, thr, None)
        assert len(threshold_episodes(r, "ttc", thr, prob, par, 0.04)) == want


def test_a_pairs_metrics_are_one_encounter():
    """A TTC episode and a PET of the same pair seconds apart are one event, named after its TTC,
    with the PET among its other metrics; another pair's stays its own."""
    ttc = {"metric": "ttc", "pair": (1, 2), "relation": "conflicting", "start": 10.0, "end": 11.4,
           "duration": 1.44, "value": 0.8, "std": 0.03, "time_extreme": 11.4, "confidence": 1.0,
           "attributes": {"metric": "ttc"}}
    pet = {**ttc, "metric": "pet", "pair": (2, 1), "start": 12.3, "end": 13.1, "duration": 0.8,
           "value": 0.8, "time_extreme": 12.3, "attributes": {"metric": "pet"}}
    other = {**ttc, "pair": (3, 4)}
    out = encounters([pet, ttc, other], 3.0)
    assert len(out) == 2
    e = next(x for x in out if set(x["pair"]) == {1, 2})
    assert e["metric"] == "ttc" and e["start"] == 10.0 and e["end"] == 13.1
    assert e["attributes"]["also"][0]["metric"] == "pet"
    assert len(encounters([pet, ttc], 0.5)) == 2


def test_events_table_keeps_its_contract(tmp_path):
    """The derived events carry the typed columns (pair, times, kind, value ± std, duration,
    collision probability ± std, relation) and validate as written."""
    import aveas_format

    rec = conflict_scene("cut_in", 1.0, method="lidar", seed=2)
    derive(rec)
    back = aveas_format.open(rec.write(tmp_path / "c.aveas"))
    ev = back.events
    for c in ("metric", "relation", "value", "value_std", "time_extreme", "duration",
              "collision_probability", "collision_probability_std"):
        assert c in ev.column_names, c
    assert set(ev.column("kind").to_pylist()) <= {"conflict", "near_miss", "hard_braking"}
    report = aveas_format.validate(back.path)
    assert report.counts["error"] == 0, [r for r in report.results if r.severity.value == "error"]
    assert isinstance(ev.column("participant_ids").type, pa.ListType)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), spread=st.floats(0.5, 30.0))
def test_the_contact_prefilter_keeps_every_contact(seed, spread):
    """The collision probability's contacts are the exact box test's on every step: the disc
    prefilter only skips steps where the footprints cannot meet (random draws, near and far,
    touching and overlapping)."""
    from aveas_format.derive.events._collision import _first_contacts
    from aveas_format.derive.interactions import ttc_boxes

    rng = np.random.default_rng(seed)
    K, M = 64, 30
    dt = np.full((1, M - 1), 0.04)

    def draws():
        x = rng.normal(0, spread, (K, 1)) + np.cumsum(rng.normal(0, 1.5, (K, M)), axis=1)
        y = rng.normal(0, spread / 4, (K, 1)) + np.cumsum(rng.normal(0, 0.5, (K, M)), axis=1)
        h = rng.uniform(-np.pi, np.pi, (K, 1)) + np.cumsum(rng.normal(0, 0.05, (K, M)), axis=1)
        return x, y, h, rng.uniform(1, 12, (K, 1)), rng.uniform(0.5, 2.6, (K, 1))

    (xa, ya, ha, La, Wa), (xb, yb, hb, Lb, Wb) = draws(), draws()
    first = ttc_boxes(xa[:, :-1], ya[:, :-1], ha[:, :-1], La, Wa, np.diff(xa, axis=1) / dt,
                      np.diff(ya, axis=1) / dt, xb[:, :-1], yb[:, :-1], hb[:, :-1], Lb, Wb,
                      np.diff(xb, axis=1) / dt, np.diff(yb, axis=1) / dt)
    want = (first <= dt).any(axis=1)
    got = _first_contacts(xa, ya, ha, La, Wa, xb, yb, hb, Lb, Wb, dt)
    np.testing.assert_array_equal(got, want)
