"""derived/criticality_summary by hand (TET, TIT, CPI, minima, counts), its std, and the DRAC
near misses of the events."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

from aveas_format.derive import criticality_summary, derive

from helpers_derive import recording

L, W = 4.0, 1.8


def _closing(gap0=40.0, dv=10.0, v_f=20.0, duration=3.0, dt=0.1, pos_std=0.0):
    """A follower closing in on its leader at ``dv``: TTC(t) = (gap0 - dv t) / dv."""
    return recording([{"x": 100.0, "y": -5.25, "length": L, "width": W, "vx": v_f, "vy": 0.0},
                      {"x": 100.0 + gap0 + L, "y": -5.25, "length": L, "width": W,
                       "vx": v_f - dv, "vy": 0.0}], duration=duration, dt=dt, pos_std=pos_std)


def _row(rec, pid):
    t = rec.derived["criticality_summary"]
    return [r for r in t.to_pylist() if r["participant_id"] == pid][0]


def test_tet_tit_by_hand():
    """TTC(t) = 4 - t from t = 0 to 3 (steps of 0.1 s); threshold 1.5 s: TTC <= 1.5 at t = 2.5 ...
    3.0, six samples of 0.1 s: TET = 0.6 s; TIT = Σ 0.1 (1.5 - (4 - t)) = 0.1 (0 + 0.1 + ... +
    0.5) = 0.15 s²."""
    rec = _closing()
    derive(rec, only=["interactions", "criticality_summary"], velocities="states", samples=0)
    r = _row(rec, 0)
    assert r["min_ttc"] == pytest.approx(1.0) and r["min_ttc_time"] == pytest.approx(3.0)
    assert r["min_ttc_other_id"] == 1 and r["min_ttc_kind"] == "lane_1d"
    assert r["ttc_samples_below"] == 6
    assert r["tet"] == pytest.approx(0.6) and r["tit"] == pytest.approx(0.15)
    assert r["tet_std"] == 0.0 and r["tit_std"] == 0.0  # exact states: no spread
    # the leader is not exposed (its follower rows are the follower's)
    lead = _row(rec, 1)
    assert lead["min_ttc"] is None and lead["tet"] == 0.0
    whole = [x for x in rec.derived["criticality_summary"].to_pylist()
             if x["scope"] == "recording"][0]
    assert whole["participant_id"] is None and whole["tet"] == pytest.approx(0.6)
    assert whole["duration_s"] == pytest.approx(2 * 3.1)
    # max DRAC at the end: 10² / (2 · 10) = 5 m/s²; min PSD = 2·3.4·10/400
    assert r["max_drac"] == pytest.approx(5.0) and r["min_psd"] == pytest.approx(0.17)


def test_threshold_from_the_parameter_and_the_recording():
    rec = _closing()
    derive(rec, only=["interactions", "criticality_summary"], velocities="states", ttc_s=3.0,
           samples=0)
    assert _row(rec, 0)["tet"] == pytest.approx(2.1)  # t = 1.0 .. 3.0: 21 samples


def test_cpi_by_hand():
    """DRAC 5 m/s² at the end of the run; with MADR ~ N(4, 0.5²) the share of time with
    DRAC > MADR is Σ dt Φ((DRAC_t - 4)/0.5) / T."""
    from scipy.special import ndtr

    rec = _closing()
    derive(rec, only=["interactions", "criticality_summary"], velocities="states",
           madr_mps2=4.0, madr_std_mps2=0.5, samples=0)
    t = np.round(np.arange(31) * 0.1, 10)
    drac = 10.0 ** 2 / (2 * (40 - 10 * t))
    # the DRAC's own std (from the velocities' 0.1 m/s) widens the MADR's
    sd = np.array([x["drac_std"] for x in rec.derived["interactions"].to_pylist()
                   if x["relation"] == "leader"])
    assert (sd > 0).all()
    expect = (0.1 * ndtr((drac - 4.0) / np.sqrt(0.5 ** 2 + sd ** 2))).sum() / 3.1
    assert _row(rec, 0)["cpi"] == pytest.approx(expect, rel=1e-6)


def test_tet_std_from_the_ttc_std():
    """With noisy positions the TTC has a std; TET's Monte Carlo std is positive and of the order
    of the TTC's std (an error shifting the whole episode by σ moves its start by σ / |dTTC/dt|
    = σ)."""
    rec = _closing(pos_std=0.3)
    derive(rec, only=["interactions", "criticality_summary"], velocities="states", samples=200)
    r = _row(rec, 0)
    it = rec.derived["interactions"].to_pylist()
    sd = np.median([x["ttc_std"] for x in it if x["relation"] == "leader" and x["ttc"] < 2])
    assert 0.3 * sd < r["tet_std"] < 3 * sd


def test_events_drac_threshold_and_surrogates_in_attributes():
    """A TTC episode and a DRAC episode of one pair at the same time are one event (an
    encounter), named after its TTC, with the DRAC among its other metrics and the other
    surrogates in its attributes; the summary counts it once."""
    rec = _closing()
    derive(rec, only=["interactions", "events", "criticality_summary"], velocities="states",
           events={"drac_mps2": 3.0})
    ev = [json.loads(a) for a in rec.events.column("attributes").to_pylist()]
    assert len(ev) == 1 and ev[0]["metric"] == "ttc"
    a = ev[0]
    assert [x["metric"] for x in a["also"]] == ["drac"]
    assert a["also"][0]["value"] == pytest.approx(5.0)
    assert a["max_drac"] == pytest.approx(5.0) and a["min_psd"] == pytest.approx(0.17)
    assert 0.0 <= a["cpi"] <= 1.0
    kind = rec.events.column("kind").to_pylist()[0]
    assert kind in ("conflict", "near_miss")
    s = criticality_summary(rec)
    assert s["conflicts"] + s["near_misses"] == 1
    assert s["tet"]["value"] == pytest.approx(0.6)
    r = _row(rec, 0)
    assert r["conflicts"] + r["near_misses"] == 1
    assert r["worst_events"] == rec.events.column("event_id").to_pylist()


def test_empty_and_write_read(tmp_path):
    import aveas_format

    rec = _closing()
    derive(rec)
    back = aveas_format.open(rec.write(tmp_path / "a.aveas"))
    t = back.derived["criticality_summary"]
    assert t.num_rows == 3 and t.schema.field("worst_events").type == pa.list_(pa.int64())
    assert aveas_format.validate(tmp_path / "a.aveas").counts["error"] == 0
