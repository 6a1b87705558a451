"""PET (``derived/encroachments``) on a junction against the truth of its motion: two
perpendicular streams of cars at constant speeds, positions with 5 cm noise, sampled at 25 Hz.
Every pair's conflict area, entry and exit times and PET are known in closed form; the derivation
finds every pair (and no other) and times them to the noise. The same with an explicit area
crossed by every track (pairs of one stream included, ``max_pet`` limiting them), with the passes
cut into tiny chunks, with two tracks inside at once and with a hole in a track's samples."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest
import shapely

from aveas_format.derive import derive
from aveas_format.mapref.build import build_recording
from aveas_format.opendrive.builder import straight_highway
from aveas_format.sample import SITE_CRS

from helpers_derive import recording, road_map

DT = 0.04
NOISE = 0.05
#: the junction's centre (the streams cross at the origin, off the map's road)
Y0 = 5000.0
#: where the streams drive: eastbound along y = -1, northbound along x = 1
EAST_Y, NORTH_X = -1.0, 1.0


def junction(n_per_stream: int = 12, seed: int = 3):
    """The recording and each car's truth: ``stream`` (0 east, 1 north), the time ``t0`` its centre
    is 40 m before the crossing line, speed ``v``, length ``L`` and width ``W``."""
    rng = np.random.default_rng(seed)
    truth = {"stream": np.repeat([0, 1], n_per_stream),
             "t0": np.concatenate([np.cumsum(rng.uniform(2.0, 6.0, n_per_stream))
                                   for _ in range(2)]),
             "v": np.concatenate([rng.uniform(10.8, 15.6, n_per_stream),
                                  rng.uniform(9.0, 13.0, n_per_stream)]),
             "L": rng.uniform(4.0, 5.0, 2 * n_per_stream),
             "W": rng.uniform(1.7, 1.9, 2 * n_per_stream)}
    cols = {k: [] for k in ("participant_id", "time", "x", "y", "heading", "vx", "vy")}
    for k, (s, t0, v) in enumerate(zip(truth["stream"], truth["t0"], truth["v"])):
        t = np.arange(np.ceil(t0 / DT), np.floor((t0 + 80.0 / v) / DT)) * DT
        d = -40.0 + v * (t - t0)  # the centre's distance past the crossing line
        east = s == 0
        cols["participant_id"].append(np.full(len(t), k))
        cols["time"].append(t)
        cols["x"].append(d if east else np.full(len(t), NORTH_X))
        cols["y"].append((np.full(len(t), EAST_Y) if east else d) + Y0)
        cols["heading"].append(np.full(len(t), 0.0 if east else np.pi / 2))
        cols["vx"].append(np.full(len(t), v if east else 0.0))
        cols["vy"].append(np.full(len(t), 0.0 if east else v))
    states = {k: np.concatenate(v) for k, v in cols.items()}
    n = len(states["time"])
    states["x"] = states["x"] + rng.normal(0, NOISE, n)
    states["y"] = states["y"] + rng.normal(0, NOISE, n)
    states["x_std"] = states["y_std"] = np.full(n, NOISE)
    m = len(truth["v"])
    parts = {"participant_id": np.arange(m), "class": ["car"] * m, "length": truth["L"],
             "width": truth["W"]}
    rec = build_recording(map_source=straight_highway(200, geo_reference=SITE_CRS),
                          participants=parts, states=states, method="infrastructure_camera",
                          partner="test", reference=False)
    return rec, truth


def _occupied(truth, k, lo, hi):
    """When car ``k``'s footprint overlaps the interval ``[lo, hi]`` along its direction (the
    other axis overlapping the area throughout): ``(enter, exit)``."""
    t0, v, L = truth["t0"][k], truth["v"][k], truth["L"][k]
    return t0 + (lo - 0.5 * L + 40.0) / v, t0 + (hi + 0.5 * L + 40.0) / v


def _expected(truth, pairs, area_of, max_pet):
    """The rows the truth gives: per pair of cars and its area (``area_of(a, b)``: the area's
    intervals along x and y), the first to enter, its exit, the second's entry and the PET (NaN
    while both are inside), the rows with a PET above ``max_pet`` left out."""
    out = {}
    for a, b in pairs:
        (x0, x1), (y0, y1) = area_of(a, b)
        occ = [_occupied(truth, k, *((x0, x1) if truth["stream"][k] == 0 else (y0, y1)))
               for k in (a, b)]
        (fa, (f_in, f_out)), (sb, (s_in, _)) = sorted(zip((a, b), occ), key=lambda o: o[1][0])
        pet = s_in - f_out
        if pet <= max_pet:
            out[(fa, sb)] = (f_out, s_in, pet if pet > 0 else np.nan)
    return out


def _check(got: pa.Table, want: dict, truth: dict, tol: float) -> None:
    rows = {(r["first_id"], r["second_id"]): r for r in got.to_pylist()}
    assert set(rows) == set(want)
    for key, (t_exit, t_enter, pet) in want.items():
        r = rows[key]
        assert r["time_first_exit"] == pytest.approx(t_exit, abs=tol), key
        assert r["time_second_enter"] == pytest.approx(t_enter, abs=tol), key
        if np.isnan(pet):
            assert r["pet"] is None and r["pet_std"] is None, key
        else:
            assert r["pet"] == pytest.approx(pet, abs=2 * tol), key
            # the PET's std: the position noise's time equivalents at both ends, NOISE / v each
            sd = np.hypot(NOISE / truth["v"][key[0]], NOISE / truth["v"][key[1]])
            assert 0.5 * sd < r["pet_std"] < 2 * sd, key
    assert list(got.column("conflict_id").to_pylist()) == list(range(got.num_rows))
    assert got.column("time_first_exit").to_pylist() == sorted(rows[k]["time_first_exit"]
                                                                for k in rows)


@pytest.fixture(scope="module")
def scene():
    return junction()


#: the times' tolerance: the noise of the footprints' edges (a few NOISE) over the slowest speed
TOL = 4 * NOISE / 9.0


def test_swept_paths_find_every_crossing_pair(scene):
    """Without areas, a pair's area is where the two streams' swept paths overlap: the northbound
    car's width along x by the eastbound car's along y. Every crossing pair with a PET up to
    ``max_pet`` and no pair of one stream (they follow, they do not cross)."""
    rec, truth = scene
    derive(rec, only="encroachments")
    n = len(truth["v"])
    east = np.flatnonzero(truth["stream"] == 0)
    north = np.flatnonzero(truth["stream"] == 1)

    def area(a, b):
        e, w = (a, b) if truth["stream"][a] == 0 else (b, a)
        return ((NORTH_X - 0.5 * truth["W"][w], NORTH_X + 0.5 * truth["W"][w]),
                (EAST_Y - 0.5 * truth["W"][e], EAST_Y + 0.5 * truth["W"][e]))

    want = _expected(truth, [(a, b) for a in east for b in north], area, 10.0)
    assert len(want) > 20 and n == 24
    _check(rec.derived["encroachments"], want, truth, TOL)


def _explicit(truth, max_pet):
    """Every pair of cars in the 6 m square around the crossing, pairs of one stream included."""
    n = len(truth["v"])
    return _expected(truth, [(a, b) for a in range(n) for b in range(a + 1, n)],
                     lambda a, b: ((-3.0, 3.0), (-3.0, 3.0)), max_pet)


def test_an_explicit_area_crossed_by_every_track(scene):
    """One area crossed by every track: all pairs of visits in it, ``max_pet`` limiting them; a
    second area that no track reaches adds nothing."""
    rec, truth = scene
    derive(rec, only="encroachments", max_pet=6.0,
           conflict_areas=[shapely.box(-3.0, Y0 - 3, 3.0, Y0 + 3).wkt,
                           shapely.box(-1e3, 0, -990, 10).wkt])
    want = _explicit(truth, 6.0)
    assert len(want) > 20 and any(truth["stream"][a] == truth["stream"][b] for a, b in want)
    _check(rec.derived["encroachments"], want, truth, TOL)


def test_tiny_chunks_give_the_truth_too(scene, monkeypatch):
    """The columnar passes are cut into chunks for memory: with tiny chunks the rows are still
    the truth's."""
    import aveas_format.derive.encroachments as enc

    rec, truth = scene
    chunks = enc._chunks
    monkeypatch.setattr(enc, "_chunks", lambda lengths, budget: chunks(lengths, 150))
    derive(rec, only="encroachments", max_pet=6.0,
           conflict_areas=[shapely.box(-3.0, Y0 - 3, 3.0, Y0 + 3).wkt])
    _check(rec.derived["encroachments"], _explicit(truth, 6.0), truth, TOL)


def test_both_inside_and_a_hole_in_the_samples():
    """Cars 0 (eastbound, 10 m/s, from x = -20) and 1 (northbound on x = 0, 10 m/s, from
    y = -15) are in the junction at once: PET null. Car 2 drives south on car 1's line (8 m/s,
    from y = 30) with a 1.5 s hole in its samples across the junction: in the explicit 4 m square
    no sample or frame puts it inside, so it has no conflict there; along the swept paths it
    shares car 1's whole line, both in it from the start (PET null)."""
    rec = recording([
        {"x": -20.0, "y": 0.0, "heading": 0.0, "length": 4.0, "width": 2.0, "vx": 10.0, "vy": 0.0},
        {"x": 0.0, "y": -15.0, "heading": np.pi / 2, "length": 4.0, "width": 2.0, "vx": 0.0,
         "vy": 10.0},
        {"x": 0.0, "y": 30.0, "heading": -np.pi / 2, "length": 4.0, "width": 2.0, "vx": 0.0,
         "vy": -8.0}], duration=6.0, shift=(0.0, 500.0), xodr=road_map())
    t = rec.states.column("time").to_numpy()
    pid = rec.states.column("participant_id").to_numpy()
    hole = (pid == 2) & (t > 3.2) & (t < 4.7)
    rec.replace_tables({"states": rec.states.filter(pa.array(~hole))})
    # (first, second): (first's exit, second's entry). Swept paths: the junction is car 1's
    # width by car 0's, |x|, |y| <= 1: car 1 in it 1.2-1.8 s, car 0 from 1.7 s; cars 1 and 2 share
    # x in [-1, 1], y in [-17, 32]: both in it at t = 0, car 1 leaves at 4.9 s. The explicit
    # square |x|, |y| <= 2: car 1 in it 1.1-1.9 s, car 0 from 1.6 s.
    for params, want in (({}, {(1, 0): (1.8, 1.7), (1, 2): (4.9, 0.0)}),
                         ({"conflict_areas": [shapely.box(-2, 498, 2, 502).wkt]},
                          {(1, 0): (1.9, 1.6)})):
        derive(rec, only="encroachments", **params)
        got = {(r["first_id"], r["second_id"]): r
               for r in rec.derived["encroachments"].to_pylist()}
        assert set(got) == set(want), params
        for key, (t_exit, t_enter) in want.items():
            r = got[key]
            assert r["pet"] is None and r["pet_std"] is None
            assert (r["time_first_exit"], r["time_second_enter"]) == pytest.approx(
                (t_exit, t_enter), abs=1e-6), (params, key)
