"""The columnar PET search (``derive/encroachments.py``) gives exactly the rows of the former
per-pair, per-area Python loop, kept here as the reference: on the benchmark's junction scene (swept
paths and one explicit area crossed by every track), on the PET cases of vectors.json and on a
track with a sampling gap."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import shapely

from aveas_format.derive import derive
from aveas_format.derive.encroachments import (EncroachmentsParams, occupancy, swept_path,
                                               track_directions)
from aveas_format.derive._samples import Samples

from helpers_derive import recording, road_map, vectors

ROOT = Path(__file__).resolve().parents[2]


def _bench():
    spec = importlib.util.spec_from_file_location("bench_derive",
                                                  ROOT / "benchmarks" / "bench_derive.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# --- the former implementation (reference) ---------------------------------------------------------

def _reference(rec, p: EncroachmentsParams) -> pa.Table:
    """``derived/encroachments`` as the loop over pairs and areas computed it."""
    S = Samples(rec)
    starts = np.r_[0, np.flatnonzero(np.diff(S.pid)) + 1]
    ends = np.r_[starts[1:], S.n]
    pids = S.pid[starts]
    tracks = [slice(a, b) for a, b in zip(starts, ends)]
    rows: dict[str, list] = {k: [] for k in ("first", "second", "t_exit", "t_enter", "pet",
                                             "pet_std", "geom")}
    if p.conflict_areas is not None:
        for area in (shapely.from_wkt(w) for w in p.conflict_areas):
            _ref_pairs_in_area(S, tracks, area, list(range(len(tracks))), p, rows)
    else:
        paths = [swept_path(S.x[sl], S.y[sl], S.L[sl.start], S.W[sl.start]) for sl in tracks]
        tree = shapely.STRtree(paths)
        a_idx, b_idx = tree.query(paths, predicate="intersects")
        mean_dir, spread = track_directions(S, tracks)
        keep = a_idx < b_idx
        dd = np.abs(np.angle(np.exp(1j * (mean_dir[a_idx] - mean_dir[b_idx]))))
        keep &= dd + spread[a_idx] + spread[b_idx] >= p.min_angle
        for a, b in zip(a_idx[keep].tolist(), b_idx[keep].tolist()):
            inter = shapely.intersection(paths[a], paths[b])
            for part in getattr(inter, "geoms", [inter]):
                if part.is_empty or part.area <= 0 or part.geom_type != "Polygon":
                    continue
                hull = part.convex_hull
                c = np.array(hull.centroid.coords[0])
                ang = []
                for tr in (tracks[a], tracks[b]):
                    k = tr.start + int(np.argmin(np.hypot(S.x[tr] - c[0], S.y[tr] - c[1])))
                    ang.append(np.arctan2(S.vy[k], S.vx[k]) if np.hypot(S.vx[k], S.vy[k]) > 0.1
                               else S.h[k])
                if abs(np.angle(np.exp(1j * (ang[0] - ang[1])))) < p.min_angle:
                    continue
                _ref_pairs_in_area(S, tracks, hull, [a, b], p, rows)
    n = len(rows["first"])
    order = np.argsort(np.asarray(rows["t_exit"], float), kind="stable") if n else np.zeros(0, int)
    pet = np.asarray([rows["pet"][i] for i in order], float)
    pstd = np.asarray([rows["pet_std"][i] for i in order], float)
    return pa.table({
        "conflict_id": pa.array(np.arange(n, dtype=np.int64)),
        "first_id": pa.array([int(pids[rows["first"][i]]) for i in order], pa.int64()),
        "second_id": pa.array([int(pids[rows["second"][i]]) for i in order], pa.int64()),
        "time_first_exit": pa.array([rows["t_exit"][i] for i in order], pa.float64()),
        "time_second_enter": pa.array([rows["t_enter"][i] for i in order], pa.float64()),
        "pet": pa.array(pet, pa.float64(), mask=~np.isfinite(pet)),
        "pet_std": pa.array(pstd, pa.float64(), mask=~np.isfinite(pstd)),
        "geometry": pa.array([rows["geom"][i] for i in order], pa.binary()),
    })


def _ref_pairs_in_area(S, tracks, area, members, p, rows) -> None:
    if area.geom_type != "Polygon":
        area = area.convex_hull
    hull = area.convex_hull
    poly = np.asarray(hull.exterior.coords)[:-1]
    if len(poly) < 3:
        return
    bx0, by0, bx1, by1 = hull.bounds
    visits = []
    for m in members:
        sl = tracks[m]
        L, W = S.L[sl.start], S.W[sl.start]
        reach = 0.5 * np.hypot(L, W)
        near = ((S.x[sl] >= bx0 - reach - 10) & (S.x[sl] <= bx1 + reach + 10)
                & (S.y[sl] >= by0 - reach - 10) & (S.y[sl] <= by1 + reach + 10))
        if not near.any():
            continue
        ii = np.flatnonzero(near)
        lo, hi = sl.start + ii[0], sl.start + ii[-1] + 1
        t_in, t_out, ke, kx = occupancy(S.t[lo:hi], S.x[lo:hi], S.y[lo:hi], S.h[lo:hi], L, W, poly,
                                        p.max_gap_s)
        if np.isfinite(t_in):
            visits.append((m, t_in, t_out, lo + ke, lo + kx))
    wkb = shapely.to_wkb(hull)
    for a in range(len(visits)):
        for b in range(a + 1, len(visits)):
            va, vb = visits[a], visits[b]
            first, second = (va, vb) if va[1] <= vb[1] else (vb, va)
            t_exit, t_enter = first[2], second[1]
            both = t_enter <= t_exit
            pet = np.nan if both else t_enter - t_exit
            if not both and pet > p.max_pet:
                continue
            sd = []
            for idx in (first[4], second[3]):
                v = np.hypot(S.vx[idx], S.vy[idx])
                u = (S.vx[idx] / v, S.vy[idx] / v) if v > 0 else (1.0, 0.0)
                var = ((u[0] * S.sx[idx]) ** 2 + (u[1] * S.sy[idx]) ** 2
                       + 2 * u[0] * u[1] * S.rxy[idx] * S.sx[idx] * S.sy[idx]
                       + 0.25 * S.sL[idx] ** 2)
                sd.append(var / v ** 2 if v > 0 else np.inf)
            rows["first"].append(first[0])
            rows["second"].append(second[0])
            rows["t_exit"].append(t_exit)
            rows["t_enter"].append(t_enter)
            rows["pet"].append(pet)
            rows["pet_std"].append(np.sqrt(sum(sd)) if not both else np.nan)
            rows["geom"].append(wkb)


# --- comparisons -----------------------------------------------------------------------------------

def _same(rec, **params) -> pa.Table:
    derive(rec, only="encroachments", **params)
    got = rec.derived["encroachments"]
    want = _reference(rec, EncroachmentsParams(**params))
    assert got.num_rows == want.num_rows
    for name in want.column_names:
        g, w = got.column(name).to_pylist(), want.column(name).to_pylist()
        assert g == w, name  # bit-identical, nulls included
    return got


@pytest.fixture(scope="module")
def junction():
    return _bench().junction_scene(n_per_stream=14)


def test_junction_swept_paths_identical(junction):
    got = _same(junction)
    assert got.num_rows > 20
    assert got.column("pet").null_count < got.num_rows


def test_junction_explicit_area_identical(junction):
    """One area crossed by every track: all pairs of visits in it, max_pet limiting them."""
    area = shapely.box(-3.0, 4997.0, 3.0, 5003.0).wkt
    got = _same(junction, conflict_areas=[area, shapely.box(-1e3, 0, -990, 10).wkt], max_pet=6.0)
    assert got.num_rows > 20


@pytest.mark.realdata
@pytest.mark.parametrize("rotate", [0.0, 0.7])
def test_vectors_pet_identical(rotate):
    v = vectors()["pet_crossing_lane_ca"]
    A, B = v["inputs"]["A"], v["inputs"]["B"]
    actors = [{"x": a["x"], "y": a["y"], "heading": a["heading_rad"], "length": a["length"],
               "width": a["width"], "vx": a["vx"], "vy": a["vy"]} for a in (A, B)]
    rec = recording(actors, duration=6.0, rotate=rotate, shift=(0.0, 500.0), xodr=road_map())
    ca = v["inputs"]["conflict_area"]
    box = shapely.box(ca["xmin"], ca["ymin"], ca["xmax"], ca["ymax"])
    box = shapely.affinity.translate(shapely.affinity.rotate(box, rotate, origin=(0, 0),
                                                             use_radians=True), 0.0, 500.0)
    assert _same(rec, conflict_areas=[box.wkt]).num_rows == 1
    assert _same(rec).num_rows == 1


def test_both_inside_and_gap_identical():
    """Both in the area at once (null PET), and a third track with a 1.5 s hole in its samples
    across the area (no frame spans the hole: it never occupies the area)."""
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
    got = _same(rec)
    assert got.column("pet").null_count >= 1
    _same(rec, conflict_areas=[shapely.box(-2, 498, 2, 502).wkt])


def test_small_chunks_identical(junction, monkeypatch):
    """The columnar passes are cut into chunks for memory; tiny chunks give the same rows."""
    import aveas_format.derive.encroachments as enc

    chunks = enc._chunks
    monkeypatch.setattr(enc, "_chunks", lambda lengths, budget: chunks(lengths, 150))
    _same(junction)
    _same(junction, conflict_areas=[shapely.box(-3.0, 4997.0, 3.0, 5003.0).wkt])
