"""Fitting OpenDRIVE roads to annotated polylines (aveas_format.opendrive.roadfit)."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from helpers_opendrive import xsd_18_errors

from aveas_format.errors import MapError
from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import curved_highway
from aveas_format.opendrive.roadfit import fit_reference_line, fit_road, road_from_lane_markings

#: stated tolerances: fitted reference line vs. the true line it was fitted to
NOISE = 0.05  # m, standard deviation of the noise on x and y
REF_TOL_NOISY = 0.06  # m, max deviation from the truth with NOISE on points every 2 m (RMS: a quarter)
REF_TOL_EXACT = 1e-6  # m, max deviation from the truth without noise (RMS: a quarter)


@lru_cache(maxsize=1)
@lru_cache(maxsize=None)
def _truth(lanes_left: int = 0):
    """Straight 120 m, clothoid 80 m, arc of radius 250 m: 600 m, lanes of 3.5 m."""
    return load_map(
        curved_highway(length=600.0, radius=250.0, straight=120.0, spiral=80.0, lanes_right=3,
                       lanes_left=lanes_left, lane_width=3.5, x0=100.0, y0=-50.0, hdg=0.3)
    )


def _line(net, t: float, step: float = 2.0, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    s = np.arange(0.0, net.roads["1"].length + 1e-9, step)
    x, y, _, _ = net.road_to_world("1", s, np.full(len(s), t))
    return np.c_[x, y] + np.random.default_rng(seed).normal(0.0, noise, (len(s), 2))


def _deviation(fitted, truth, t_true: float) -> np.ndarray:
    """Distances of the fitted reference line (sampled every 0.3 m) from the true line at t_true."""
    ss = np.linspace(0.0, fitted.roads["1"].length, 2000)
    x, y, _, _ = fitted.reference_line("1", ss)
    pr = truth.world_to_road(x, y)
    assert pr.on_road.mean() > 0.99  # the ends may lie a few cm beyond the true road's ends
    return np.abs(pr.t[pr.on_road] - t_true)


@pytest.mark.parametrize("t,noise,tol,seed", [(0.0, 0.0, REF_TOL_EXACT, 0), (-5.25, NOISE, REF_TOL_NOISY, 0),
                                               (-5.25, NOISE, REF_TOL_NOISY, 1)])
def test_reference_line_recovers_line_clothoid_arc(t, noise, tol, seed):
    truth = _truth()
    pts = _line(truth, t, noise=noise, seed=seed)
    fit = fit_road([pts])
    ref = fit.reference_line
    assert ref.snapped and {"spiral", "arc"} <= set(ref.kinds) and len(ref.geometries) <= 4
    if noise == 0:  # the very records of the original
        assert [(g.kind, round(g.length, 6)) for g in ref.geometries] == [("line", 120.0), ("spiral", 80.0), ("arc", 400.0)]
        assert ref.geometries[2].params["curvature"] == pytest.approx(1 / 250, rel=1e-9)
    # continuous heading and curvature from record to record (G2)
    net = fit.network()
    g = net.roads["1"].geometries
    ends = [gg.s + gg.length for gg in g[:-1]]
    for s_end in ends:
        _, _, h, k = net.reference_line("1", [s_end - 1e-7, s_end + 1e-7])
        assert abs(h[1] - h[0]) < 1e-6 and abs(k[1] - k[0]) < 1e-6
    assert [f.code for f in net.check() if f.code.startswith("geometry")] == []
    dev = _deviation(net, truth, t)
    assert dev.max() < tol and np.sqrt(np.mean(dev**2)) < tol / 4
    assert ref.rms == pytest.approx(noise, rel=0.2, abs=1e-6)


def test_centre_lines_give_lanes_where_they_should():
    truth = _truth()
    centres = [_line(truth, t, noise=NOISE, seed=i) for i, t in enumerate((-1.75, -5.25, -8.75))]
    # given in a shuffled order: they are sorted across the road
    fit = fit_road([centres[2], centres[0], centres[1]], kind="centres", driving="right")
    assert fit.order == [1, 2, 0] and fit.reference == 2
    assert xsd_18_errors(fit.xodr) == []
    assert fit.line_lane == [-3, -1, -2] and fit.lane_ids == [-1, -2, -3]
    net = fit.network()
    for t, lid in ((-1.75, -1), (-5.25, -2), (-8.75, -3)):
        exact = _line(truth, t, step=5.0)[2:-2]  # noise-free points, away from the road's ends
        pr = net.world_to_road(exact[:, 0], exact[:, 1])
        assert (pr.lane_id == lid).all()
        assert np.abs(pr.lane_offset).max() < 0.05
        noisy = centres[-lid - 1][3:-3]
        pr = net.world_to_road(noisy[:, 0], noisy[:, 1])
        assert (pr.lane_id == lid).all() and np.abs(pr.lane_offset).max() < 5 * NOISE
    inner, outer = net.lane_borders("1", np.linspace(5, 590, 50), -2)
    np.testing.assert_allclose(inner - outer, 3.5, atol=0.06)
    assert fit.network().roads["1"].lane_offset  # reference on the centre of lane -2


def test_lane_markings_both_directions_validate_and_load():
    truth = load_map(curved_highway(length=500.0, radius=-300.0, straight=100.0, spiral=60.0,
                                    lanes_right=2, lanes_left=2))
    s = np.arange(0.0, 500.0 + 1e-9, 3.0)
    marks = []
    for i, t in enumerate((7.0, 3.5, 0.0, -3.5, -7.0)):
        x, y, _, _ = truth.road_to_world("1", s, np.full(len(s), t))
        marks.append(np.c_[x, y] + np.random.default_rng(i).normal(0, 0.03, (len(s), 2)))
    fit = road_from_lane_markings(marks, driving="both", geo_reference="+proj=tmerc +lat_0=49 +lon_0=8")
    assert fit.reference == 2 and fit.lane_ids == [2, 1, -1, -2]
    assert xsd_18_errors(fit.xodr) == []
    net = load_map(fit.xodr)
    assert net.header.version == "1.8" and net.header.geo_reference.startswith("+proj=tmerc")
    assert [f for f in net.check() if f.severity == "error"] == []
    road = net.roads["1"]
    assert road.lane_offset == []  # the reference line is the centre marking
    sec = road.lane_sections[0]
    assert [ln.road_marks[0].type for ln in sec.left] == ["broken", "solid"]
    assert sec.center.road_marks[0].type == "solid"
    smp = truth.sample_lane_points(3000, seed=2)
    x, y, _, _ = truth.road_to_world(smp["road_id"], smp["s"], smp["t"])
    pr = net.world_to_road(x, y)
    on = pr.on_road
    assert on.mean() > 0.99
    assert (pr.lane_id[on] == smp["lane_id"][on]).all()


def test_two_point_markings_make_a_straight_road():
    """highD-style: straight markings given by their end points, one direction."""
    marks = [np.array([[0.0, y], [420.0, y]]) for y in (20.0, 16.2, 12.4, 8.6)]
    fit = road_from_lane_markings(marks, driving="right", reference=0, speed_limit=130 / 3.6,
                                  road_type="motorway")
    net = fit.network()
    road = net.roads["1"]
    assert [g.kind for g in road.geometries] == ["line"] and road.length == pytest.approx(420.0)
    assert road.lane_offset == [] and [ln.widths.shape[0] for ln in road.lane_sections[0].right] == [1, 1, 1]
    pr = net.world_to_road([10.0, 10.0, 10.0], [18.1, 14.3, 10.5])
    np.testing.assert_array_equal(pr.lane_id, [-1, -2, -3])
    np.testing.assert_allclose(pr.lane_offset, 0.0, atol=1e-9)
    assert road.types[0].speed_max_ms == pytest.approx(130 / 3.6)
    assert xsd_18_errors(fit.xodr) == []


def test_sparse_vertices_and_a_single_centre_line(tmp_path):
    truth = _truth()
    pts = _line(truth, -1.75, step=25.0)
    fit = fit_road([pts], lane_width=3.0)
    net = load_map(fit.write(tmp_path / "one.xodr"))
    assert fit.max_error < 0.01 and fit.lane_ids == [-1]
    inner, outer = net.lane_borders("1", [100.0], -1)
    assert inner[0] - outer[0] == pytest.approx(3.0)
    pr = net.world_to_road(pts[1:-1, 0], pts[1:-1, 1])
    assert (pr.lane_id == -1).all() and np.abs(pr.lane_offset).max() <= fit.max_error + 1e-9


_X = np.linspace(0.0, 100.0, 51)
_T = np.linspace(-np.pi, np.pi, 120)


@pytest.mark.parametrize(
    "call,needle",
    [
        (lambda: fit_reference_line([[0.0, 0.0]]), "has 1 distinct point(s); a line needs at least 2"),
        (lambda: fit_reference_line([[0.0, 0.0], [0.0, 0.0]]), "needs at least 2"),
        (lambda: fit_reference_line([[0.0, 0.0], [1.0, np.nan]]), "point 1 (1.0, nan) is not finite"),
        (lambda: fit_reference_line([1.0, 2.0, 3.0]), "expected an (N, 2) array"),
        (lambda: fit_reference_line(np.c_[_X, 0.01 * _X**1.5][np.random.default_rng(0).permutation(51)]),
         "not ordered along the line"),
        (lambda: fit_reference_line(np.c_[10 * _T - 30 * np.sin(_T), -30 * np.cos(_T)]), "intersects itself near"),
        (lambda: fit_road([np.c_[_X, 0 * _X], np.c_[_X, 3.5 - 0.07 * _X], np.c_[_X, 0 * _X - 3.5]], kind="borders"),
         "cross or touch near s="),
        (lambda: road_from_lane_markings([np.c_[_X, 0 * _X - 3.5], np.c_[_X, 0 * _X], np.c_[_X, 0 * _X + 3.5]]),
         "must be ordered left to right"),
        (lambda: road_from_lane_markings([np.c_[_X, 0 * _X + 3.5], np.c_[_X, 0 * _X], np.c_[_X + 500, 0 * _X - 3.5]]),
         "does not run alongside the reference line"),
        (lambda: road_from_lane_markings([np.c_[_X, 0 * _X]]), "need at least 2 line(s)"),
        (lambda: fit_road([np.c_[20 * np.cos(_T / 4), 20 * np.sin(_T / 4)], np.c_[60 * np.cos(_T / 4), 60 * np.sin(_T / 4)]]),
         "beyond its tightest curve radius"),
    ],
)
def test_malformed_input_is_a_clear_error(call, needle):
    with pytest.raises(MapError) as exc:
        call()
    assert needle in str(exc.value)
    assert isinstance(exc.value, ValueError)


def test_bad_options():
    line = np.c_[_X, 0 * _X]
    with pytest.raises(ValueError, match="kind must be"):
        fit_road([line], kind="middles")
    with pytest.raises(ValueError, match="driving must be"):
        fit_road([line], driving="left")
    with pytest.raises(ValueError, match="mark_types needs 3"):
        road_from_lane_markings([line + [0, 3.5], line, line - [0, 3.5]], mark_types=["solid"])
