"""Rotating or translating the whole scene changes neither TTC, THW nor PET."""

from __future__ import annotations

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.derive import derive
from aveas_format.derive.interactions import ttc_boxes

from helpers_derive import recording, road_map, row

angle = st.floats(-np.pi, np.pi, allow_nan=False)
offset = st.floats(-5000, 5000, allow_nan=False)


def _rot(x, y, th, dx, dy):
    c, s = np.cos(th), np.sin(th)
    return c * x - s * y + dx, s * x + c * y + dy


@settings(max_examples=300, deadline=None)
@given(th=angle, dx=offset, dy=offset,
       ax=st.floats(-30, 30), ay=st.floats(-30, 30), ah=angle, bx=st.floats(-30, 30),
       by=st.floats(-30, 30), bh=angle, avx=st.floats(-20, 20), avy=st.floats(-20, 20),
       bvx=st.floats(-20, 20), bvy=st.floats(-20, 20))
def test_box_ttc_invariant(th, dx, dy, ax, ay, ah, bx, by, bh, avx, avy, bvx, bvy):
    base = float(ttc_boxes(ax, ay, ah, 4.5, 1.8, avx, avy, bx, by, bh, 5.0, 2.0, bvx, bvy))
    pa_ = _rot(ax, ay, th, dx, dy)
    pb_ = _rot(bx, by, th, dx, dy)
    va = _rot(avx, avy, th, 0, 0)
    vb = _rot(bvx, bvy, th, 0, 0)
    moved = float(ttc_boxes(*pa_, ah + th, 4.5, 1.8, *va, *pb_, bh + th, 5.0, 2.0, *vb))
    # grazing contact (edges exactly touching, or a relative speed of 1e-130 m/s towards each
    # other): a micrometre less of size changes the answer, and so may the rounding of a move
    shrunk = float(ttc_boxes(ax, ay, ah, 4.5 - 1e-6, 1.8 - 1e-6, avx, avy, bx, by, bh, 5.0 - 1e-6,
                             2.0 - 1e-6, bvx, bvy))
    grazing = np.isinf(shrunk) != np.isinf(base) or (
        np.isfinite(base) and abs(shrunk - base) > 1e-3 * max(1.0, base))
    # a closing speed within the rounding of a rotated velocity (here 2e-16 m/s: a TTC of 1e15 s)
    # is ill-conditioned: the rotation's rounding changes it by its own size
    closing = np.hypot(bvx - avx, bvy - avy)
    ill = closing < 1e-9 * max(1.0, np.hypot(avx, avy), np.hypot(bvx, bvy))
    if grazing:
        pass
    elif ill:  # (boxes that overlap now stay overlapping: 0 either way)
        assert base >= 0 and moved >= 0 and (base == 0) == (moved == 0)
    elif np.isinf(base) or np.isinf(moved):
        # grazing contact may flip under rounding; otherwise both are inf
        assert np.isinf(base) == np.isinf(moved) or min(base, moved) > 0
    else:
        assert moved == pytest.approx(base, abs=1e-6 * max(1.0, base))
    # symmetric in the pair
    swapped = float(ttc_boxes(bx, by, bh, 5.0, 2.0, bvx, bvy, ax, ay, ah, 4.5, 1.8, avx, avy))
    assert swapped == base or abs(swapped - base) < 1e-9


@settings(max_examples=6, deadline=None)
@given(th=angle, dx=st.floats(-2000, 2000), dy=st.floats(-2000, 2000),
       gap=st.floats(5, 80), vf=st.floats(5, 40), vl=st.floats(0, 40))
def test_lane_ttc_thw_invariant(th, dx, dy, gap, vf, vl):
    """The same car-following scene on a road at any angle and place: same TTC, THW, gap."""
    actors = [{"x": 100.0, "y": -1.75, "length": 4.5, "width": 1.8, "vx": vf, "vy": 0.0},
              {"x": 100.0 + gap + 4.5, "y": -1.75, "length": 4.5, "width": 1.8, "vx": vl,
               "vy": 0.0}]
    out = []
    for rot, shift in ((0.0, (0.0, 0.0)), (th, (dx, dy))):
        rec = recording(actors, duration=0.2, rotate=rot, shift=shift)
        derive(rec, only="interactions", box_2d=False, velocities="states")
        r = row(rec.derived["interactions"], participant_id=0, time=0.0, relation="leader")[0]
        out.append(r)
    a, b = out
    assert b["gap"] == pytest.approx(a["gap"], abs=1e-6)
    assert b["thw"] == pytest.approx(a["thw"], abs=1e-6)
    if a["ttc"] is None:
        assert b["ttc"] is None
    else:
        assert b["ttc"] == pytest.approx(a["ttc"], abs=1e-6)
        assert a["ttc"] == pytest.approx(gap / (vf - vl), abs=1e-6)


@settings(max_examples=5, deadline=None)
@given(th=angle, dx=st.floats(-1000, 1000), dy=st.floats(-1000, 1000))
def test_pet_invariant(th, dx, dy):
    actors = [{"x": -16.0, "y": 0.0, "heading": 0.0, "length": 4.0, "width": 2.0, "vx": 10.0,
               "vy": 0.0},
              {"x": 0.0, "y": -41.5, "heading": np.pi / 2, "length": 4.0, "width": 2.0,
               "vx": 0.0, "vy": 12.5}]
    pets = []
    for rot, shift in ((0.0, (0.0, 3000.0)), (th, (dx, 3000.0 + dy))):
        rec = recording(actors, duration=6.0, rotate=rot, shift=shift, xodr=road_map())
        area = shapely.affinity.translate(
            shapely.affinity.rotate(shapely.box(-2, -2, 2, 2), rot, origin=(0, 0),
                                    use_radians=True), *shift)
        derive(rec, only="encroachments", conflict_areas=[area.wkt])
        pets.append(rec.derived["encroachments"].to_pylist()[0]["pet"])
        derive(rec, only="encroachments")
        swept = rec.derived["encroachments"].to_pylist()[0]["pet"]
        pets.append(swept)
    assert pets[2] == pytest.approx(pets[0], abs=1e-6)
    assert pets[3] == pytest.approx(pets[1], abs=1e-6)
