"""The figures of a recording (aveas_format.plot.recording) and the lane colours of the map plot."""

from __future__ import annotations

import re

import matplotlib
import numpy as np
import pytest
from matplotlib.collections import PolyCollection

import aveas_format
import helpers_validate as vf
from aveas_format.plot.map import LANE_COLORS
from aveas_format.plot.recording import (
    CLASS_COLORS,
    acceleration_histogram,
    longitudinal_acceleration,
    map_figure,
    png_bytes,
    recording_name,
    robust_range,
    speed_histogram,
)


def _legend_texts(fig) -> list[str]:
    return [t.get_text() for leg in fig.legends for t in leg.get_texts()]


@pytest.fixture(scope="module")
def broken():
    sc = vf.fresh()
    sc["tracks"][0]["x"][75:] += 3.0            # kinematics.position_jump (error, x/y)
    sc["participants"]["length"][2] = 19.0       # participants.size_implausible (no position)
    sc["tracks"][3]["vx"][60:90] *= 2.5          # kinematics.acceleration + jerk
    rec = vf.build(sc)
    return rec, aveas_format.validate(rec)


def _in_all(fig, kind: str) -> list:
    """The collections of type ``kind`` of every axes of the figure (a strip each)."""
    return [c for ax in fig.axes for c in ax.collections if type(c).__name__ == kind]


def test_map_figure_by_class_direction_regions_and_one_marker_per_rule(broken):
    rec, report = broken
    fig = map_figure(rec, report.findings())
    ax = fig.axes[0]
    assert ax.get_title().startswith("clean recording for the rule tests")  # the title, not the id
    texts = _legend_texts(fig)
    assert {"car (2)", "truck (1)", "van (1)", "direction of travel", "coverage"} <= set(texts)
    assert "unobserved: occlusion (1, 5.96 s)" in texts
    # trajectories in their class colours
    colours = {matplotlib.colors.to_hex(line.get_color()) for a in fig.axes for line in a.get_lines()}
    assert {CLASS_COLORS["car"], CLASS_COLORS["truck"], CLASS_COLORS["van"]} <= colours
    # arrows in the direction of travel, along +x (all drive in +x): at least one per participant
    quivers = _in_all(fig, "Quiver")
    assert sum(q.N for q in quivers) >= 4 and all(np.all(q.U > 0.99) for q in quivers)
    # located findings: one marker shape per rule, its legend entry names the rule
    located = {c: n for c, n in ((t.rsplit(" (", 1)[0], t) for t in texts) if "." in c}
    assert set(located) == {"kinematics.position_jump", "kinematics.acceleration",
                            "kinematics.jerk"}
    markers = [h.get_marker() for leg in fig.legends for h in leg.legend_handles
               if h.get_label() in located.values()]
    assert len(set(markers)) == len(markers) == 3
    # the unobserved region and the coverage are drawn
    polys = [c for a in fig.axes for c in a.collections if type(c) is PolyCollection]
    assert any(np.allclose(p.get_paths()[0].vertices.min(0), [900.0, -10.5]) for p in polys)


def test_map_figure_keeps_x_and_y_at_one_scale_and_no_road_label(broken):
    """Issue 42: the map is drawn at equal scale (0.1 m of noise must not look like hair): a
    1 km stretch 14 m wide is cut into strips stacked like lines of text, each at aspect 1, that
    together cover the data; no road id is written over the data."""
    rec, report = broken
    fig = map_figure(rec, report.findings())
    assert len(fig.axes) > 1 and "strips along x, equal scale" in fig.axes[0].get_title()
    assert all(ax.get_aspect() == 1.0 for ax in fig.axes)
    lims = np.array([ax.get_xlim() for ax in fig.axes])
    x = rec.states.column("x").to_numpy()
    assert lims[:, 0].min() <= x.min() and lims[:, 1].max() >= x.max()
    assert np.all(lims[1:, 0] < lims[:-1, 1])  # consecutive strips overlap: nothing falls between
    png_bytes(fig)  # drawn: the axes boxes take their aspect
    for ax in fig.axes:  # the height drawn is the width drawn / the data's ratio: equal scale
        bb = ax.get_window_extent()
        (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
        assert (bb.height / bb.width) == pytest.approx((y1 - y0) / (x1 - x0), rel=0.05)
        assert not [t for t in ax.texts if t.get_text() in rec.map.roads]  # no road label


def _short_scene(steps: int):
    """The four participants for ``steps`` samples near x = 20-160 m of the 1000 m test map,
    without a coverage polygon; the truck stands still."""
    sc = vf.fresh()
    sc["meta"]["coverage"] = None
    sc["unobserved"] = None
    sc["tracks"] = [vf.track(x0, lane, 0.0 if cls == "truck" else v, steps=steps)
                    for cls, lane, x0, v, _, _ in vf.VEHICLES]
    sc["meta"]["duration_s"] = (steps - 1) / vf.RATE
    return sc


def test_map_figure_shows_the_data_not_the_whole_map_and_a_dot_for_who_stands():
    """A few seconds on a long road: the axes hold the trajectories (with a margin), not the
    1000 m of map; the standing truck (no arrow, a trajectory of zero length) is a dot."""
    fig = map_figure(vf.build(_short_scene(50)))
    lims = np.array([ax.get_xlim() for ax in fig.axes])
    x0, x1 = lims[:, 0].min(), lims[:, 1].max()
    assert -30 < x0 < 20 and 190 < x1 < 320  # data: x 20..~200 m; the map: 0..1000 m
    dots = _in_all(fig, "PathCollection")
    assert dots and all(np.allclose(d.get_offsets(), [[20.0, -1.75]]) for d in dots)
    assert matplotlib.colors.to_hex(dots[0].get_facecolors()[0]) == CLASS_COLORS["truck"]
    assert "standing (speed < 0.5 m/s)" in _legend_texts(fig)
    assert sum(q.N for q in _in_all(fig, "Quiver")) >= 3


def test_empty_histograms_say_why():
    rec = vf.build(_short_scene(5))  # 0.16 s per participant: no 0.5 s acceleration baseline
    ax = acceleration_histogram(rec).axes[0]
    assert [t.get_text() for t in ax.texts] == ["no participant has two samples 0.5 s or more "
                                                "apart"]
    assert len(speed_histogram(rec).axes[0].texts) == 0  # speeds there are


def test_recording_name_prefers_title_then_file_name(broken, tmp_path):
    rec, _ = broken
    assert recording_name(rec) == "clean recording for the rule tests"
    sc = vf.fresh()
    sc["meta"]["title"] = None
    path = vf.build(sc).write(tmp_path / "site-a.aveas")
    assert recording_name(aveas_format.open(path)) == "site-a"
    assert recording_name(vf.build(sc)) == "validate-clean"


def test_robust_range_counts_what_it_leaves_out():
    v = np.r_[np.linspace(0, 10, 1000), 5000.0, np.nan]
    lo, hi, outside = robust_range(v)
    assert lo == pytest.approx(0.05, abs=0.01) and hi == pytest.approx(9.95, abs=0.01)
    assert outside == 10  # 5 below, 5 above the percentiles (the wild value among them)
    assert robust_range(np.array([-1.0, 2.0]), include=0.0)[:2] == pytest.approx((-0.985, 1.985))


def test_speed_histogram_is_clipped_and_says_how_many_values_are_outside():
    sc = vf.fresh()
    sc["tracks"][1]["vx"][10:12] = 300.0  # two wild velocities
    ax = speed_histogram(vf.build(sc)).axes[0]
    assert ax.get_ylabel() == "density [1/(km/h)]"  # km/h: what traffic people read
    assert ax.get_xlim()[1] < 150  # not stretched to 1,080 km/h
    assert re.search(r"^speed \[km/h\]\n2 of 600 values outside \[\d+, \d+\]", ax.get_xlabel())


def test_speed_histogram_spans_the_speeds_not_zero_to_them():
    """Issue 42: motorway speeds (79-119 km/h here) fill the axis, in whole 5 km/h, instead of a
    range from 0 that leaves its left half empty; every value is inside it."""
    ax = speed_histogram(vf.build(vf.fresh())).axes[0]
    lo, hi = ax.get_xlim()
    assert 60 <= lo <= 79 and 119 <= hi <= 140 and lo % 5 == 0 and hi % 5 == 0
    assert "all 600 values" in ax.get_xlabel()


def test_longitudinal_acceleration_is_signed():
    """A car braking from 20 to 10 m/s in 2 s and one accelerating: -5 and +5 m/s² (not |a|)."""
    t = np.arange(0, 2.0001, 0.04)
    v = np.r_[20 - 5 * t, 10 + 5 * t]
    st = {"participant_id": np.repeat(np.array([2**60 + 1, 2**60 + 2], np.int64), len(t)),
          "time": np.r_[t, t], "vx": v, "vy": np.zeros(2 * len(t))}
    i, a = longitudinal_acceleration(st, 0.5)
    first = st["participant_id"][i] == 2**60 + 1
    assert np.allclose(a[first], -5.0) and np.allclose(a[~first], 5.0)
    assert len(i) == 2 * (len(t) - 13)  # no difference across participants


def test_acceleration_histogram_shows_braking_and_accelerating(broken):
    rec, _ = broken
    ax = acceleration_histogram(rec).axes[0]
    assert ax.get_ylabel() == "density [1/(m/s²)]"
    assert ax.get_xlim()[0] < 0 < ax.get_xlim()[1]
    assert {"← braking", "accelerating →"} <= {t.get_text() for t in ax.texts}


def test_lane_types_have_distinguishable_colours():
    """entry/exit/onRamp/offRamp and driving/bidirectional each have their own colour."""
    groups = [("entry", "exit", "onRamp", "offRamp", "driving", "bidirectional")]
    for types in groups:
        rgb = np.array([matplotlib.colors.to_rgb(LANE_COLORS[t]) for t in types])
        d = np.linalg.norm(rgb[:, None] - rgb[None], axis=-1)
        assert d[np.triu_indices(len(types), 1)].min() > 0.12, types
