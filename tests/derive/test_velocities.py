"""Interactions take the along-motion velocity from derived/kinematics' smoothed speed where its
std is smaller than the measured one (``velocities="auto"``): closing speed and TTC against the
truth of the noisy highway scene; exact velocities stay as they are."""

from __future__ import annotations

import copy

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pytest

from aveas_format.derive import derive
from aveas_format.sample import highway_scene


@pytest.fixture(scope="module")
def scene():
    rec, truth = highway_scene(n_vehicles=60, duration_s=40.0, seed=7, return_truth=True)
    derive(rec, only="kinematics")
    return rec, truth


def _leaders(rec, states, mode):
    r = copy.copy(rec)
    r.derived = {"kinematics": rec.derived["kinematics"]}
    r.replace_tables({"states": states})
    derive(r, only="interactions", interactions={"box_2d": False, "velocities": mode})
    it = r.derived["interactions"]
    it = it.filter(pc.equal(it["relation"], "leader"))
    return it.select(["participant_id", "time", "other_id", "ttc", "ttc_std", "closing_speed"]).to_pandas()


def test_smoothed_speed_beats_noisy_measured_velocity(scene):
    rec, truth = scene
    exact = rec.states
    for name in ("vx", "vy"):
        exact = exact.set_column(exact.schema.get_field_index(name), name, pa.array(truth[name]))
    ref = _leaders(rec, exact, "states")
    err = {}
    for mode in ("states", "auto", "smoothed"):
        m = ref.merge(_leaders(rec, rec.states, mode), on=["participant_id", "time", "other_id"],
                      suffixes=("_t", ""))
        assert len(m) == len(ref)  # the relations themselves do not depend on the velocities
        err[mode] = float(np.sqrt(np.mean((m.closing_speed - m.closing_speed_t) ** 2)))
        ok = np.isfinite(m.ttc_t) & (m.ttc_t < 30) & np.isfinite(m.ttc)
        rel = np.abs(m.ttc - m.ttc_t)[ok] / m.ttc_t[ok]
        cover = float((np.abs(m.ttc - m.ttc_t) <= m.ttc_std)[ok].mean())
        if mode == "states":
            assert np.median(rel) > 0.04 and 0.6 < cover < 0.76
        else:
            assert np.median(rel) < 0.015 and 0.6 < cover < 0.86
    # measured velocities: 0.2 m/s noise each -> ~0.28 m/s on the closing speed; smoothed: ~0.02
    assert err["states"] > 0.2 and err["auto"] < 0.05 and err["smoothed"] < 0.05


def test_exact_velocities_are_kept(scene):
    """With a velocity std of 0 the measured velocity is the better one: auto changes nothing."""
    rec, truth = scene
    st = rec.states
    for name, v in (("vx", truth["vx"]), ("vy", truth["vy"]), ("vx_std", np.zeros(st.num_rows)),
                    ("vy_std", np.zeros(st.num_rows))):
        st = st.set_column(st.schema.get_field_index(name), name, pa.array(v))
    a, b = _leaders(rec, st, "states"), _leaders(rec, st, "auto")
    np.testing.assert_array_equal(a.closing_speed.to_numpy(), b.closing_speed.to_numpy())
