"""Geometry: every plan-view type against closed forms or independent quadrature; profiles; lanes."""

from __future__ import annotations

import numpy as np
import pytest
from helpers_opendrive import CONTINUOUS_MAPS, fixture_map, real_map
from scipy.integrate import quad

from aveas_format.opendrive import load_map


def _quad_xy(heading, s):
    """Position by adaptive quadrature of (cos, sin) of a heading function (independent check)."""
    x = quad(lambda u: np.cos(heading(u)), 0.0, s, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
    y = quad(lambda u: np.sin(heading(u)), 0.0, s, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
    return x, y


def test_line(geom_net):
    s = np.linspace(0, 100, 11)
    x, y, h, k = geom_net.reference_line("line", s)
    np.testing.assert_allclose(x, s, atol=1e-12)
    np.testing.assert_allclose(y, 0.0, atol=1e-12)
    assert (h == 0).all() and (k == 0).all()


def test_arc_closed_form(geom_net):
    s = np.linspace(0, 150, 31)
    x, y, h, k = geom_net.reference_line("arc", s)
    kk = 0.01
    np.testing.assert_allclose(x, np.sin(kk * s) / kk, atol=1e-9)
    np.testing.assert_allclose(y, 100.0 + (1 - np.cos(kk * s)) / kk, atol=1e-9)
    np.testing.assert_allclose(h, kk * s, atol=1e-12)
    np.testing.assert_allclose(k, kk)


@pytest.mark.parametrize("road_id", ["spiral", "spiral_flat", "spiral_tiny"])
def test_spirals_against_quadrature(geom_net, road_id):
    g = geom_net.roads[road_id].geometries[0]
    k0, k1 = g.params["curv_start"], g.params["curv_end"]
    c = (k1 - k0) / g.length
    s = np.linspace(0, g.length, 9)
    x, y, h, k = geom_net.reference_line(road_id, s)
    for si, xi, yi in zip(s, x, y):
        qx, qy = _quad_xy(lambda u: g.hdg + k0 * u + c * u * u / 2, si)
        assert abs(g.x + qx - xi) < 1e-9 and abs(g.y + qy - yi) < 1e-9
    np.testing.assert_allclose(h, g.hdg + k0 * s + c * s * s / 2, atol=1e-12)
    np.testing.assert_allclose(k, k0 + c * s, atol=1e-15)


def test_spiral_paths_agree(geom_net):
    """Fresnel and Gauss-Legendre evaluate the same clothoid to well below a micrometre."""
    pv = geom_net.plan
    gi = int(np.flatnonzero(pv.kind == 2)[0])
    assert pv.use_fresnel[gi]
    ds = np.linspace(0, pv.length[gi], 50)
    g = np.full(50, gi)
    xf, yf, _, _, _ = pv.evaluate(g, ds)
    pv.use_fresnel[gi] = False
    try:
        xg, yg, _, _, _ = pv.evaluate(g, ds)
    finally:
        pv.use_fresnel[gi] = True
    assert np.max(np.hypot(xf - xg, yf - yg)) < 1e-9


def test_degenerate_spirals_use_quadrature(geom_net):
    pv = geom_net.plan
    idx = {r: i for i, r in enumerate(geom_net.road_ids)}
    assert not pv.use_fresnel[idx["spiral_flat"]] and not pv.use_fresnel[idx["spiral_tiny"]]


def _arc_length(du, dv, p):
    return quad(lambda q: np.hypot(du(q), dv(q)), 0.0, p, epsabs=1e-13, epsrel=1e-13)[0]


def test_poly3_is_arc_length_parametrised(geom_net):
    g = geom_net.roads["poly3"].geometries[0]
    a, b, c, d = (g.params[k] for k in "abcd")
    dv = lambda u: b + 2 * c * u + 3 * d * u * u  # noqa: E731
    s = np.array([0.0, 10.0, 42.0, 77.0, 100.0])
    x, y, h, _ = geom_net.reference_line("poly3", s)
    ch, sh = np.cos(g.hdg), np.sin(g.hdg)
    u = (x - g.x) * ch + (y - g.y) * sh
    v = -(x - g.x) * sh + (y - g.y) * ch
    np.testing.assert_allclose(v, a + b * u + c * u**2 + d * u**3, atol=1e-9)  # on the curve
    for si, ui in zip(s, u):
        assert abs(_arc_length(lambda q: 1.0, dv, ui) - si) < 1e-9  # at arc length s
    np.testing.assert_allclose(h, g.hdg + np.arctan(dv(u)), atol=1e-12)


def test_parampoly3_arclength_is_rescaled_true_arc_length(geom_net):
    g = geom_net.roads["ppoly_arclength"].geometries[0]
    P = {k: g.params[k] for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
    du = lambda p: P["bU"] + 2 * P["cU"] * p + 3 * P["dU"] * p * p  # noqa: E731
    dv = lambda p: P["bV"] + 2 * P["cV"] * p + 3 * P["dV"] * p * p  # noqa: E731
    total = _arc_length(du, dv, g.length)
    assert total > g.length + 1e-3  # the curve is longer than p's range: rescaling matters
    s = np.array([0.0, 25.0, 50.0, 99.0, 100.0])
    x, y, h, _ = geom_net.reference_line("ppoly_arclength", s)
    ch, sh = np.cos(g.hdg), np.sin(g.hdg)
    u = (x - g.x) * ch + (y - g.y) * sh
    p = u  # U(p) = p in this fixture
    for si, pi in zip(s, p):
        assert abs(_arc_length(du, dv, pi) - si * total / g.length) < 1e-9
    np.testing.assert_allclose(h, g.hdg + np.arctan2(dv(p), du(p)), atol=1e-12)
    assert p[-1] == pytest.approx(g.length, abs=1e-9)  # the end of the geometry is p = length


def test_parampoly3_normalized_is_rescaled_true_arc_length(geom_net):
    """pRange normalized: p in [0, 1], the point at s is the one at true arc length
    s * A(1) / length, as esmini (calcS2PMap) and libOpenDRIVE read it (issue 18, point 6);
    checked against an independent adaptive quadrature (scipy quad) + root finding (brentq)."""
    from scipy.optimize import brentq

    g = geom_net.roads["ppoly_normalized"].geometries[0]
    P = {k: g.params[k] for k in ("aU", "bU", "cU", "dU", "aV", "bV", "cV", "dV")}
    du = lambda p: P["bU"] + 2 * P["cU"] * p + 3 * P["dU"] * p * p  # noqa: E731
    dv = lambda p: P["bV"] + 2 * P["cV"] * p + 3 * P["dV"] * p * p  # noqa: E731
    total = _arc_length(du, dv, 1.0)
    s = np.linspace(0, g.length, 7)
    p = np.array([0.0 if si == 0 else brentq(lambda q: _arc_length(du, dv, q) - si * total / g.length,
                                             0.0, 1.0, xtol=1e-14) for si in s])
    U = P["aU"] + P["bU"] * p + P["cU"] * p**2 + P["dU"] * p**3
    V = P["aV"] + P["bV"] * p + P["cV"] * p**2 + P["dV"] * p**3
    x, y, h, _ = geom_net.reference_line("ppoly_normalized", s)
    np.testing.assert_allclose(x, g.x + U * np.cos(g.hdg) - V * np.sin(g.hdg), atol=1e-9)
    np.testing.assert_allclose(y, g.y + U * np.sin(g.hdg) + V * np.cos(g.hdg), atol=1e-9)
    np.testing.assert_allclose(h, g.hdg + np.arctan2(dv(p), du(p)), atol=1e-12)
    # and the linear reading (p = s / length) is measurably different on this fixture
    lin = s / g.length
    Ul = P["aU"] + P["bU"] * lin + P["cU"] * lin**2 + P["dU"] * lin**3
    assert np.max(np.abs(Ul - U)) > 1e-3


@pytest.mark.parametrize("road_id", ["arc", "spiral", "spiral_tiny", "poly3", "ppoly_arclength", "ppoly_normalized"])
def test_curvature_is_heading_rate(geom_net, road_id):
    L = geom_net.roads[road_id].length
    s = np.linspace(1.0, L - 1.0, 13)
    e = 1e-4
    _, _, h1, _ = geom_net.reference_line(road_id, s - e)
    _, _, h2, k = geom_net.reference_line(road_id, s + e)
    _, _, _, k = geom_net.reference_line(road_id, s)
    np.testing.assert_allclose((h2 - h1) / (2 * e), k, atol=1e-7)


def test_elevation_and_superelevation(geom_net):
    s = np.array([0.0, 30.0, 90.0])
    t = np.array([0.0, -2.0, 1.5])
    x, y, z, h = geom_net.road_to_world("line", s, t, h=0.5)
    np.testing.assert_allclose(z, 1.0 + 0.01 * s + t * np.tan(0.02) + 0.5)
    np.testing.assert_allclose(y, t)
    _, _, z2, _ = geom_net.road_to_world("sections", [10.0, 70.0], [0.0, 2.0])
    np.testing.assert_allclose(z2, [2.0, 2.0 + 0.02 * 10 + 2.0 * np.tan(0.001 * 10)])


def test_lane_borders_width_records(geom_net):
    s = np.array([0.0, 50.0, 100.0])
    inner, outer = geom_net.lane_borders("line", s, -2)
    np.testing.assert_allclose(inner, -3.5)
    np.testing.assert_allclose(outer, -3.5 - (3.0 + 0.01 * s))
    lane, off = geom_net.lane_at("line", s, np.array([1.0, -4.0, -7.0]))
    assert lane.tolist() == [1, -2, -2]
    np.testing.assert_allclose(off, [1.0 - 1.5, -4.0 + 3.5 + (3.0 + 0.5) / 2, -7.0 + 3.5 + 4.0 / 2])
    lane, off = geom_net.lane_at("line", [10.0, 10.0], [3.5, -20.0])  # off the road
    assert lane.tolist() == [0, 0] and np.isnan(off).all()


def test_lane_borders_border_records(geom_net):
    """<border> gives the outer border's t from the reference line; <width> wins over <border>."""
    s = np.array([0.0, 40.0, 80.0])
    _, o1 = geom_net.lane_borders("border", s, 1)
    np.testing.assert_allclose(o1, 3.0 + 0.01 * s)
    i2, o2 = geom_net.lane_borders("border", s, 2)
    np.testing.assert_allclose(i2, o1)
    np.testing.assert_allclose(o2, 7.0)
    im1, om1 = geom_net.lane_borders("border", s, -1)
    np.testing.assert_allclose(im1, 0.5)  # the centre lane sits at laneOffset
    np.testing.assert_allclose(om1, np.where(s < 50, -3.5, -3.5 - 0.02 * (s - 50)))
    _, om2 = geom_net.lane_borders("border", s, -2)
    np.testing.assert_allclose(om2, om1 - 3.0)
    lane, _ = geom_net.lane_at("border", s, np.array([0.7, 5.0, -6.0]))
    assert lane.tolist() == [1, 2, -2]


def test_lane_offset_sections_and_tiny_section(geom_net):
    s = np.array([10.0, 40.0, 50.004, 95.0])
    inner, outer = geom_net.lane_borders("sections", s, -1)
    lo = np.array([0.0, 0.001 * 100 - 1e-5 * 1000, 0.001 * 20.004**2 - 1e-5 * 20.004**3, 0.63])
    np.testing.assert_allclose(inner, lo, atol=1e-12)
    np.testing.assert_allclose(outer, lo - 3.5, atol=1e-12)
    # lane -2 of the last section narrows from 3.0 to 1.0 between ds = 20 and 60
    _, o2 = geom_net.lane_borders("sections", [50.0078 + 40.0], -2)
    lo2 = 0.63  # the laneOffset record from s = 90 on
    np.testing.assert_allclose(o2, lo2 - 3.5 - (3.0 - 0.05 * 20.0), atol=1e-9)


def test_continuity_of_real_maps(real_net):
    """Consecutive geometries meet their declared starts to 1e-6 m where the file is continuous."""
    pv = real_net.plan
    xe, ye, he = pv.end_points()
    same = pv.road[:-1] == pv.road[1:]
    gap = np.hypot(xe[:-1] - pv.x0[1:], ye[:-1] - pv.y0[1:])[same]
    name = real_net.path.rsplit("/", 1)[-1]
    if len(gap) == 0:
        return
    if name in CONTINUOUS_MAPS:
        assert gap.max() <= 1e-6
    else:
        # these files carry their own mm-sized gaps (their exporters round); most joints are exact
        assert gap.max() < 2e-3
        assert (gap <= 1e-6).mean() > 0.6


@pytest.mark.realdata
def test_spirals_of_a_real_map_against_quadrature():
    net = real_map("qc-opendrive__Ex_Entry_Exit.xodr")
    pv = net.plan
    for gi in np.flatnonzero(pv.kind == 2)[:6]:
        k0, L, h0 = pv.k0[gi], pv.length[gi], pv.h0[gi]
        c = (pv.k1[gi] - k0) / L
        qx, qy = _quad_xy(lambda u, h0=h0, k0=k0, c=c: h0 + k0 * u + c * u * u / 2, L)
        x, y, _, _, _ = pv.evaluate(np.array([gi]), np.array([L]))
        assert np.hypot(pv.x0[gi] + qx - x[0], pv.y0[gi] + qy - y[0]) < 1e-9


def test_reference_line_vectorised_over_roads(geom_net):
    rid = np.array(["line", "arc", "line"], dtype=object)
    x, y, z, h = geom_net.road_to_world(rid, [1.0, 0.0, 2.0], 0.0)
    np.testing.assert_allclose(x, [1.0, 0.0, 2.0], atol=1e-12)
    np.testing.assert_allclose(y, [0.0, 100.0, 0.0], atol=1e-12)
    with pytest.raises(KeyError, match="nope"):
        geom_net.reference_line("nope", [0.0])


def test_reader_geometry_of_builder_is_exact():
    from aveas_format.opendrive.builder import curved_highway

    net = load_map(curved_highway(length=500.0, radius=200.0, straight=100.0, spiral=50.0, hdg=0.3, x0=5.0, y0=-7.0))
    _, _, h, k = net.reference_line("1", [0.0, 100.0, 150.0, 500.0])
    np.testing.assert_allclose(h, [0.3, 0.3, 0.3 + 50 / 400, 0.3 + 50 / 400 + 350 / 200], atol=1e-12)
    np.testing.assert_allclose(k, [0.0, 0.0, 1 / 200, 1 / 200], atol=1e-15)
    assert fixture_map("geometry_types.xodr").roads["arc"].length == 150.0
