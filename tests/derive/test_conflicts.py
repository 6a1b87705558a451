"""derived/conflicts' crossing measures by hand (SUMO's definitions, docs/derive.md "Crossing
conflicts"); the comparison with SUMO itself is tests/sim/test_ssm.py."""

from __future__ import annotations

import numpy as np
import pytest

from aveas_format.derive.conflicts import crossing_measures, entry_time


def test_crossing_by_hand():
    """A 10 m before the area at 10 m/s, B 12 m before it at 10 m/s, both areas 6.8 m long:
    A enters at 1 s and leaves at 1.68 s, B enters at 1.2 s: TTC = 12/10, DRAC = 2 (10 - 12/1.68)
    / 1.68, PPET = 1.2 - 1.68."""
    ttc, drac, ppet, a_first = crossing_measures(*(np.array([v]) for v in
                                                   (10.0, 10.0, 0.0, 6.8, 12.0, 10.0, 0.0, 6.8)))
    assert a_first[0]
    assert ttc[0] == pytest.approx(1.2)
    assert drac[0] == pytest.approx(2 * (10 - 12 / 1.68) / 1.68)
    assert ppet[0] == pytest.approx(-0.48)


def test_no_overlap_and_braking():
    # B 30 m away: enters at 3 s, after A left at 1.68 s: no TTC, PPET 1.32 s
    ttc, drac, ppet, _ = crossing_measures(*(np.array([v]) for v in
                                             (10.0, 10.0, 0.0, 6.8, 30.0, 10.0, 0.0, 6.8)))
    assert np.isnan(ttc[0]) and np.isnan(drac[0]) and ppet[0] == pytest.approx(1.32)
    # braking at 2 m/s² from 10 m/s stops after 25 m: an entry 30 m ahead is never reached
    assert entry_time(30.0, 10.0, -2.0) == np.inf
    assert entry_time(16.0, 10.0, -2.0) == pytest.approx(2.0)  # 10 t - t² = 16


def test_second_already_inside_is_contact():
    """Both inside the area at once (A entered first, B's front past its entry): TTC 0, never
    negative; DRAC undefined."""
    ttc, drac, _, a_first = crossing_measures(*(np.array([v]) for v in
                                                (-2.0, 10.0, 0.0, 6.8, -0.5, 10.0, 0.0, 6.8)))
    assert a_first[0] and ttc[0] == 0.0 and np.isnan(drac[0])
