"""The figures of a recording (aveas_format.plot.recording) and the lane colours of the map plot."""

from __future__ import annotations

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


def test_map_figure_by_class_direction_regions_and_one_marker_per_rule(broken):
    rec, report = broken
    fig = map_figure(rec, report.findings())
    ax = fig.axes[0]
    assert ax.get_title() == "clean recording for the rule tests"  # the title, not the id
    texts = _legend_texts(fig)
    assert {"car (2)", "truck (1)", "van (1)", "direction of travel", "coverage"} <= set(texts)
    assert "unobserved: occlusion (1, 5.96 s)" in texts
    # trajectories in their class colours
    colours = {matplotlib.colors.to_hex(line.get_color()) for line in ax.get_lines()}
    assert {CLASS_COLORS["car"], CLASS_COLORS["truck"], CLASS_COLORS["van"]} <= colours
    # one arrow per participant, pointing along +x (all drive in +x)
    (quiver,) = [c for c in ax.collections if type(c).__name__ == "Quiver"]
    assert quiver.N == 4 and np.all(quiver.U > 0.99)
    # located findings: one marker shape per rule, its legend entry names the rule
    located = {c: n for c, n in ((t.rsplit(" (", 1)[0], t) for t in texts) if "." in c}
    assert set(located) == {"kinematics.position_jump", "kinematics.acceleration",
                            "kinematics.jerk"}
    markers = [h.get_marker() for leg in fig.legends for h in leg.legend_handles
               if h.get_label() in located.values()]
    assert len(set(markers)) == len(markers) == 3
    # the unobserved region and the coverage are drawn
    polys = [c for c in ax.collections if type(c) is PolyCollection]
    assert any(np.allclose(p.get_paths()[0].vertices.min(0), [900.0, -10.5]) for p in polys)


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
    ax = fig.axes[0]
    x0, x1 = ax.get_xlim()
    assert -30 < x0 < 20 and 190 < x1 < 320  # data: x 20..~200 m; the map: 0..1000 m
    dots = [c for c in ax.collections if type(c).__name__ == "PathCollection"]
    assert len(dots) == 1 and np.allclose(dots[0].get_offsets(), [[20.0, -1.75]])
    assert matplotlib.colors.to_hex(dots[0].get_facecolors()[0]) == CLASS_COLORS["truck"]
    assert "standing (speed < 0.5 m/s)" in _legend_texts(fig)
    (quiver,) = [c for c in ax.collections if type(c).__name__ == "Quiver"]
    assert quiver.N == 3


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
    assert ax.get_ylabel() == "density [1/(m/s)]"
    assert ax.get_xlim()[1] < 40  # not stretched to 300 m/s
    assert "2 of 600 values outside [0, 33]" in ax.get_xlabel()


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
