"""Every OpenDRIVE map under ../shared/data: it reads, ``map check`` finds no error (unless the map
is defective: then the finding is asserted), world -> road -> world returns sampled lane points,
and paramPoly3 geometries agree with an independent evaluation of esmini's / libOpenDRIVE's
reading (true arc length rescaled to the geometry's length, issue 18 point 6)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from aveas_format.opendrive import load_map
from helpers_realdata import real_files

MAPS = real_files("**/*.xodr")

#: maps that are defective themselves: the error findings map check must report
DEFECTIVE = {
    # the ASAM OpenDRIVE 1.8 example links lanes that the linked roads do not have (road 292 has
    # no lane -4, road 308 no lane -5)
    "qc-opendrive__Ex_Entry_Exit.xodr": [
        ("link.missing_lane", "junction 1: connection 1 links lane -4 -> -6, not both present"),
        ("link.missing_lane", "junction 2: connection 0 links lane -5 -> -5, not both present")],
}


def _load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # lenient geoReference readings
        return load_map(path)


@pytest.mark.parametrize("path", MAPS)
def test_map_reads_and_checks(path):
    net = _load(path)
    assert net.roads
    errors = sorted((f.code, f.message) for f in net.check() if f.severity == "error")
    assert errors == sorted(DEFECTIVE.get(path.name, []))


@pytest.mark.parametrize("path", MAPS)
def test_world_road_world_round_trip(path):
    net = _load(path)
    pts = net.sample_lane_points(300, seed=7)
    x, y, _, _ = net.road_to_world(pts["road_id"], pts["s"], pts["t"])
    pr = net.world_to_road(x, y)
    assert pr.on_road.all()
    # back to the world from whichever road the projection chose (junctions overlap)
    xb, yb, _, _ = net.road_to_world(pr.road_id, pr.s, pr.t)
    assert np.max(np.hypot(xb - x, yb - y)) < 1e-6
    same = pr.road_id.astype(str) == pts["road_id"].astype(str)
    assert same.mean() > 0.6
    assert np.max(np.abs(pr.s[same] - pts["s"][same])) < 1e-6
    assert np.max(np.abs(pr.t[same] - pts["t"][same])) < 1e-6


def _reference_pp3(g, s_local: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x, y of a paramPoly3 at local s, computed independently: arc length A(p) by adaptive
    quadrature (scipy quad), p of s by root finding (brentq) on A(p) = s A(p_max) / length."""
    P = g.params
    du = lambda p: P["bU"] + 2 * P["cU"] * p + 3 * P["dU"] * p * p  # noqa: E731
    dv = lambda p: P["bV"] + 2 * P["cV"] * p + 3 * P["dV"] * p * p  # noqa: E731
    arc = lambda p: quad(lambda q: np.hypot(du(q), dv(q)), 0.0, p, epsabs=1e-12, epsrel=1e-12)[0]  # noqa: E731
    p_max = g.length if P["p_range"] == "arcLength" else 1.0
    total = arc(p_max)
    p = np.array([0.0 if s <= 0 else p_max if s >= g.length else
                  brentq(lambda q: arc(q) - s * total / g.length, 0.0, p_max, xtol=1e-14)
                  for s in s_local])
    u = P["aU"] + P["bU"] * p + P["cU"] * p**2 + P["dU"] * p**3
    v = P["aV"] + P["bV"] * p + P["cV"] * p**2 + P["dV"] * p**3
    c, s_ = np.cos(g.hdg), np.sin(g.hdg)
    return g.x + u * c - v * s_, g.y + u * s_ + v * c


PP3_MAPS = [p for p in MAPS if p.values[0] is not None
            and b"paramPoly3" in p.values[0].read_bytes()] or MAPS[:1]


@pytest.mark.parametrize("path", PP3_MAPS)
def test_parampoly3_agrees_with_an_independent_arc_length(path):
    """Both pRange values (normalized on the SUMO map, arcLength on esmini's): road -> world and
    world -> road agree with the independent reference to 1e-6 m over 5 points of up to 40
    geometries per map. (CARLA's own map engine agrees to 1.6 mm: docs/opendrive.md.)"""
    net = _load(path)
    rng = np.random.default_rng(3)
    geoms = [(rid, g) for rid, r in net.roads.items() for g in r.geometries if g.kind == "paramPoly3"]
    assert geoms
    for rid, g in [geoms[i] for i in sorted(rng.choice(len(geoms), min(40, len(geoms)), replace=False))]:
        s_local = np.linspace(0.0, g.length, 5) * 0.999
        xr, yr = _reference_pp3(g, s_local)
        x, y, _, _ = net.reference_line(rid, g.s + s_local)
        assert np.max(np.hypot(x - xr, y - yr)) < 1e-6, (rid, g.s)
        pr = net.world_to_road(xr, yr)
        on = pr.road_id.astype(str) == rid
        assert np.max(np.abs(pr.s[on] - (g.s + s_local[on])), initial=0.0) < 1e-6


@pytest.mark.parametrize("path", MAPS)
def test_map_commands_end_without_an_internal_error(path, tmp_path, capsys):
    """``map info``, ``map check`` and ``map plot`` on every real map: a summary, a report and an
    image, never an internal error. The CARLA towns hold the degenerate classes of
    tests/opendrive/test_odr_degenerate.py: roads and lane sections of 2e-7 to 3e-4 m, which
    ``map check`` reports (``lane.section_length``) and the plot passes over."""
    import json

    from aveas_format.cli.app import app
    from aveas_format.cli.common import run

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert run(app, ["map", "info", str(path), "--format", "json"]) == 0
        info = json.loads(capsys.readouterr().out)
        rc = run(app, ["map", "check", str(path), "--format", "json"])
        report = json.loads(capsys.readouterr().out)
        assert rc == (1 if path.name in DEFECTIVE else 0)
        out = tmp_path / "map.png"
        assert run(app, ["map", "plot", str(path), "-o", str(out), "--step", "2"]) == 0
    assert "internal error" not in capsys.readouterr().err
    assert info["roads"] == len(_load(path).roads) and out.stat().st_size > 10_000
    short = [f for f in report["findings"] if f["code"] == "lane.section_length"]
    assert all(f["line"] and f["value"] < 1e-3 for f in short)
    if path.name.startswith("opendrive-test-files__Town"):
        assert short  # CARLA writes sub-millimetre connecting roads
