"""An OpenDRIVE map built from the paths that participants drive (:func:`map_from_tracks`).

1. **Flow** (:mod:`.flow`): moving vehicles' points (a sample of at most ``max_points``) give the
   carriageways (traffic of one direction) and the junction areas (where directions cross).
2. **Reference line** of each carriageway: a walk along its traffic (every ``step`` m: the median
   lateral position and the mean heading of the points within +-``step`` m ahead and behind,
   both ways from its densest cell), fitted by the clothoid spline of :mod:`.reference` (lines,
   arcs, spirals) within ``reference_tol``.
3. **Lanes**: the points' lateral offsets from it, per ``bin_length`` m of road: the peaks of their
   histogram (0.1 m bins, smoothed) at least ``min_spacing`` m apart are the lane centres (each
   the mean of its points within 0.8 m). The lane count, smoothed along the road, cuts the road
   into lane sections (none shorter than ``min_section`` m); in each, lane centres are followed
   in order across the road. Borders lie half-way between neighbouring centres, the outer ones
   half the neighbouring spacing out (``lane_width`` for a road of one lane). A lane that ends
   narrows to nothing over the last ``taper`` m of its section; one that begins widens from
   nothing. Borders are piecewise cubics within ``tol`` (:mod:`.assemble`).
4. **Junctions**: every turning movement that at least ``min_tracks`` tracks drive (from the end of
   one carriageway, through a junction area, to the start of another) is one connecting road, one
   lane wide: it starts at the centre of the lane those tracks leave, ends at the centre of the lane
   they enter, with those lanes' headings and widths, and follows their median path between
   (:mod:`.hermite`, within ``reference_tol``).
5. **Fit report**: every sampled point referenced to the built map (with its heading): per road and
   lane, how many points and how far from the lane centre (RMS, p95); the share on a lane.

Roads are one-way (right lanes, driving along s); a carriageway's reference line runs with its
traffic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.errors import MapError
from aveas_format.opendrive.model import Connection, Junction, LaneLink, Road, RoadLink, RoadType
from aveas_format.opendrive.roadfit.assemble import Frame, LaneSpec, SectionSpec, lane_sections, link_sections
from aveas_format.opendrive.roadfit.flow import flow_field
from aveas_format.opendrive.roadfit.hermite import hermite_chain
from aveas_format.opendrive.roadfit.reference import fit_reference_line


@dataclass
class BuildOptions:
    """The stated tolerances and thresholds of :func:`map_from_tracks` (see the module doc)."""

    min_speed: float = 2.0
    max_points: int = 1_500_000
    cell: float = 2.0
    step: float = 4.0
    reference_tol: float = 0.1
    tol: float = 0.05
    bin_length: float = 10.0
    min_spacing: float = 2.2
    min_section: float = 30.0
    taper: float = 30.0
    lane_width: float = 3.5
    min_tracks: int = 3
    seed: int = 0


@dataclass
class MapBuild:
    """A built map: the OpenDRIVE text, what was built and how well it fits (``report``)."""

    xodr: str
    roads: int
    junctions: int
    connecting_roads: int
    lanes: int
    report: dict[str, Any] = field(default_factory=dict)

    def network(self):
        from aveas_format.opendrive.network import load_map

        return load_map(self.xodr)

    def write(self, path):
        from aveas_format.safeio import write_text_atomic

        return write_text_atomic(path, self.xodr)


# -- 1. the points -------------------------------------------------------------------------------
def motion(track: np.ndarray, time: np.ndarray, x: np.ndarray, y: np.ndarray):
    """Order by (track, time) and the motion of each point from its neighbours in its track:
    (order, heading, speed); speed 0 for a track's single point."""
    order = np.lexsort((time, track))
    tr, t, xx, yy = track[order], time[order], x[order], y[order]
    n = len(tr)
    prev = np.r_[0, np.arange(n - 1)]
    nxt = np.r_[np.arange(1, n), n - 1]
    prev = np.where(tr[prev] == tr, prev, np.arange(n))
    nxt = np.where(tr[nxt] == tr, nxt, np.arange(n))
    dx, dy, dt = xx[nxt] - xx[prev], yy[nxt] - yy[prev], t[nxt] - t[prev]
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(dt > 0, np.hypot(dx, dy) / dt, 0.0)
    return order, np.arctan2(dy, dx), speed


# -- 2. reference lines --------------------------------------------------------------------------
def _walk(tree, px, py, ph, start: np.ndarray, h0: float, step: float, reach: float, direction: int,
          max_steps: int = 20000) -> list[np.ndarray]:
    out = []
    p, h = start.copy(), h0
    for _ in range(max_steps):
        idx = tree.query_ball_point(p, reach)
        if len(idx) < 3:
            break
        idx = np.asarray(idx)
        c, s = math.cos(h), math.sin(h)
        dx, dy = px[idx] - p[0], py[idx] - p[1]
        along = dx * c + dy * s
        lat = -dx * s + dy * c
        dh = np.mod(ph[idx] - h + np.pi, 2 * np.pi) - np.pi
        ok = (np.abs(along) <= step) & (np.abs(dh) < math.radians(45))
        if ok.sum() < 3:
            break
        p = p + float(np.median(lat[ok])) * np.array([-s, c])
        h = h + float(np.arctan2(np.mean(np.sin(dh[ok])), np.mean(np.cos(dh[ok]))))
        out.append(p.copy())
        p = p + direction * step * np.array([math.cos(h), math.sin(h)])
        if len(out) > 10 and np.hypot(*(p - out[0])) < step:
            break  # a ring: back at the start
    return out


def reference_path(px, py, ph, step: float) -> np.ndarray:
    """The walk along a carriageway's points (see the module doc): an ordered polyline."""
    from scipy.spatial import cKDTree

    if len(px) > 60_000:  # the walk takes medians: a sample does as well and keeps the queries small
        keep = np.random.default_rng(0).choice(len(px), 60_000, replace=False)
        px, py, ph = px[keep], py[keep], ph[keep]
    tree = cKDTree(np.column_stack([px, py]))
    # start in the densest part: the point with most neighbours among a few hundred
    probe = np.linspace(0, len(px) - 1, min(len(px), 300)).astype(np.int64)
    dens = [len(v) for v in tree.query_ball_point(np.column_stack([px[probe], py[probe]]), step)]
    k = int(probe[int(np.argmax(dens))])
    start = np.array([px[k], py[k]])
    h0 = float(ph[k])
    reach = 4.0 * step + 20.0
    fwd = _walk(tree, px, py, ph, start, h0, step, reach, 1)
    back = _walk(tree, px, py, ph, start, h0, step, reach, -1)
    pts = back[::-1][:-1] + fwd if back and fwd else (fwd or back)
    pts = np.array(pts)
    if len(pts) >= 2:
        keep = np.r_[True, np.hypot(*np.diff(pts, axis=0).T) > 1e-6]
        pts = pts[keep]
    return pts


def _smooth(path: np.ndarray, sigma: float) -> np.ndarray:
    """The walk smoothed along it (Gaussian over ``sigma`` points; the ends kept)."""
    from scipy.ndimage import gaussian_filter1d

    if len(path) < 5:
        return path
    out = gaussian_filter1d(path, sigma, axis=0, mode="nearest")
    out[[0, -1]] = path[[0, -1]]
    return out


# -- 3. lanes --------------------------------------------------------------------------------------
def _peaks(t: np.ndarray, min_spacing: float, min_count: int) -> np.ndarray:
    """Lane centres in one bin of road: histogram peaks of the lateral offsets (module doc)."""
    if len(t) < min_count:
        return np.zeros(0)
    lo, hi = np.floor(t.min()) - 1.0, np.ceil(t.max()) + 1.0
    edges = np.arange(lo, hi + 0.1, 0.1)
    h, _ = np.histogram(t, edges)
    k = np.exp(-0.5 * (np.arange(-6, 7) * 0.1 / 0.25) ** 2)
    hs = np.convolve(h, k / k.sum(), mode="same")
    centres = 0.5 * (edges[:-1] + edges[1:])
    cand = np.flatnonzero((hs >= np.roll(hs, 1)) & (hs > np.roll(hs, -1)) & (hs >= 0.15 * hs.max()))
    cand = cand[np.argsort(-hs[cand])]
    chosen: list[int] = []
    for c in cand:
        if all(abs(centres[c] - centres[o]) >= min_spacing for o in chosen):
            chosen.append(int(c))
    out = []
    for c in chosen:
        near = np.abs(t - centres[c]) <= 0.8
        if near.sum() >= min_count:
            out.append(float(np.mean(t[near])))
    return np.sort(np.array(out))[::-1]  # left to right


def _runs(values: np.ndarray) -> list[tuple[int, int, int]]:
    """(start, stop, value) of the runs of equal values."""
    cut = np.flatnonzero(np.diff(values) != 0) + 1
    starts = np.r_[0, cut]
    stops = np.r_[cut, len(values)]
    return [(int(a), int(b), int(values[a])) for a, b in zip(starts, stops)]


def lane_layout(s: np.ndarray, t: np.ndarray, length: float, o: BuildOptions):
    """Lane sections of a carriageway from its points' (s, t): ``[(s0, s1, centres)]`` with
    ``centres`` an array (bins of the section, lanes) of lane-centre t (NaN where not seen) and the
    bin positions."""
    nb = max(1, int(np.ceil(length / o.bin_length)))
    edges = np.linspace(0.0, length, nb + 1)
    b = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, nb - 1)
    order = np.argsort(b, kind="stable")
    bounds = np.searchsorted(b[order], np.arange(nb + 1))
    min_count = max(5, int(0.02 * len(s) / nb))
    peaks = [_peaks(t[order[bounds[k]:bounds[k + 1]]], o.min_spacing, min_count) for k in range(nb)]
    count = np.array([len(p) for p in peaks])
    # smooth the lane count along the road: a running median over 5 bins, then runs shorter
    # than min_section merged into the longer neighbour
    from scipy.ndimage import median_filter

    seen = count > 0
    if not seen.any():
        return [], edges
    cnt = count.copy()
    cnt[~seen] = np.round(np.interp(np.flatnonzero(~seen), np.flatnonzero(seen), count[seen])).astype(int)
    cnt = median_filter(cnt, size=5, mode="nearest")
    min_bins = max(1, int(round(o.min_section / o.bin_length)))
    for _ in range(len(cnt)):
        runs = _runs(cnt)
        short = [r for r in runs if r[1] - r[0] < min_bins]
        if not short or len(runs) == 1:
            break
        a, z, _ = min(short, key=lambda r: r[1] - r[0])
        i = runs.index(next(r for r in runs if r[0] == a))
        left = runs[i - 1] if i > 0 else None
        right = runs[i + 1] if i + 1 < len(runs) else None
        nb_run = max([r for r in (left, right) if r is not None], key=lambda r: r[1] - r[0])
        cnt[a:z] = nb_run[2]
    out = []
    for a, z, n in _runs(cnt):
        cen = np.full((z - a, n), np.nan)
        for k in range(a, z):
            if len(peaks[k]) == n:
                cen[k - a] = peaks[k]
        out.append((float(edges[a]), float(edges[z]), cen, 0.5 * (edges[a:z] + edges[a + 1:z + 1])))
    return out, edges


def _fill(mid: np.ndarray, col: np.ndarray) -> np.ndarray:
    ok = np.isfinite(col)
    if not ok.any():
        return col
    from scipy.ndimage import median_filter

    v = np.interp(mid, mid[ok], col[ok])
    return median_filter(v, size=3, mode="nearest")


# -- the build -------------------------------------------------------------------------------------
def map_from_tracks(x, y, track, time, *, heading=None, vehicle=None, geo_reference: str | None = None,
                    options: BuildOptions | None = None, name: str = "built from trajectories") -> MapBuild:
    """Build an OpenDRIVE map from trajectories (see the module doc). ``x``/``y`` in a local
    metric frame, ``track``: a track id per point, ``time`` in seconds, ``heading`` optional (the
    direction of motion is used), ``vehicle``: a mask of the points of vehicles (default: all)."""
    from aveas_format.opendrive.builder import roads_xodr

    o = options or BuildOptions()
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    tr = np.unique(np.asarray(track), return_inverse=True)[1].astype(np.int64)
    tm = np.asarray(time, dtype=np.float64)
    order, h, v = motion(tr, tm, x, y)
    x, y, tr, tm = x[order], y[order], tr[order], tm[order]
    keep = (v >= o.min_speed) & np.isfinite(x) & np.isfinite(y)
    if heading is not None:
        # a recorded heading that the motion disagrees with by more than 30 degrees marks a jump
        # (a simulator's instant lane change, a tracking error): such points are left out
        hd = np.asarray(heading, dtype=np.float64)[order]
        keep &= np.abs(np.mod(h - hd + np.pi, 2 * np.pi) - np.pi) < math.radians(30)
    if vehicle is not None:
        keep &= np.asarray(vehicle, dtype=bool)[order]
    idx = np.flatnonzero(keep)
    if len(idx) > o.max_points:
        rng = np.random.default_rng(o.seed)
        idx = np.sort(rng.choice(idx, o.max_points, replace=False))
    if len(idx) < 50:
        raise MapError(f"too few moving vehicle points to build a map from ({len(idx)} faster than "
                       f"{o.min_speed:g} m/s)")
    px, py, ph, pt, ptm = x[idx], y[idx], h[idx], tr[idx], tm[idx]
    flow = flow_field(px, py, ph, cell=o.cell)
    roads: list[Road] = []
    cw: dict[int, dict[str, Any]] = {}
    next_id = [1]

    def new_id() -> str:
        next_id[0] += 1
        return str(next_id[0] - 1)

    for c in range(flow.n_carriageways):
        sel = np.flatnonzero(flow.carriageway == c)
        if len(np.unique(pt[sel])) < o.min_tracks:
            continue
        path = reference_path(px[sel], py[sel], ph[sel], o.step)
        if len(path) < 3:
            continue
        path = _smooth(path, 2)
        try:
            ref = fit_reference_line(path, tolerance=o.reference_tol, knot_spacing=max(40.0, 10 * o.step),
                                     snap_tolerance=o.reference_tol / 2)
        except (MapError, ValueError, np.linalg.LinAlgError):
            continue
        frame = Frame(ref.geometries, reach=60.0)
        s, t = frame.project(px[sel], py[sel])
        ok = (s >= 0) & (s <= frame.length) & (np.abs(t) < 30.0)
        built = _carriageway_road(new_id(), frame, s[ok], t[ok], o)
        if built is None:
            continue
        road, specs = built
        roads.append(road)
        cw[c] = {"road": road, "specs": specs, "frame": frame,
                 "fit": {"rms_m": round(ref.rms, 4), "max_m": round(ref.max_error, 4), "geometries": ref.kinds}}
    # junctions: movements through junction areas
    junctions, connecting = _junctions(flow, px, py, ph, pt, ptm, cw, o, new_id)
    roads += connecting
    if not roads:
        raise MapError("no road could be built from the trajectories (too few tracks per carriageway?)")
    xodr = roads_xodr(roads, junctions, name=name, geo_reference=geo_reference)
    build = MapBuild(xodr, len(roads), len(junctions), len(connecting),
                     sum(len(s.left) + len(s.right) for r in roads for s in r.lane_sections))
    build.report = fit_report(build.network(), px, py, ph, seed=o.seed)
    # the reference lines against the walks they were fitted to
    build.report["reference_lines"] = {c["road"].id: c["fit"] for c in cw.values()}
    build.report["options"] = {k: getattr(o, k) for k in o.__dataclass_fields__}
    build.report["points"] = {"given": int(len(x)), "moving_vehicles": int(keep.sum()), "used": int(len(idx))}
    return build


def _carriageway_road(rid: str, frame: Frame, s: np.ndarray, t: np.ndarray, o: BuildOptions):
    layout, _ = lane_layout(s, t, frame.length, o)
    if not layout:
        return None
    specs: list[SectionSpec] = []
    pairs: list[list[tuple[int, int]]] = []
    prev_centres = None
    for k, (s0, s1, cen, mid) in enumerate(layout):
        n = cen.shape[1]
        cols = [_fill(mid, cen[:, j]) for j in range(n)]
        C = np.array(cols)  # (lanes, bins), left to right
        if n == 1:
            half = np.full(C.shape[1], o.lane_width / 2)
            B = [C[0] + half, C[0] - half]
        else:
            B = [1.5 * C[0] - 0.5 * C[1]] + [0.5 * (C[j - 1] + C[j]) for j in range(1, n)] + \
                [1.5 * C[-1] - 0.5 * C[-2]]
        ss = np.r_[s0, mid, s1]
        borders = [(ss, np.r_[b[0], b, b[-1]]) for b in B]
        specs.append(SectionSpec(s0, s1, borders, 0, [LaneSpec("driving", outer_mark="broken") for _ in range(n)]))
        if prev_centres is not None:
            pc = prev_centres[:, -1]
            nc = C[:, 0]
            plist = []
            for i, c in enumerate(pc):
                j = int(np.argmin(np.abs(nc - c)))
                if abs(nc[j] - c) < 1.5 and all(p[1] != j for p in plist):
                    plist.append((i, j))
            pairs.append(plist)
            _taper(specs[-2], [i for i in range(len(pc)) if i not in {p[0] for p in plist}], o.taper, end=True)
            _taper(specs[-1], [j for j in range(len(nc)) if j not in {p[1] for p in plist}], o.taper, end=False)
        prev_centres = C
    for sp in specs:
        sp.lanes[-1].outer_mark = "solid"
    offset, secs = lane_sections(specs, o.tol, pairs)
    road = Road(id=rid, length=frame.length, types=[RoadType(0.0, "unknown")], geometries=frame.geoms,
                lane_offset=offset, lane_sections=secs)
    for sec in secs:
        sec.center.road_marks[0].type = "solid"
    link_sections(road, pairs, specs)
    return road, specs


def _taper(spec: SectionSpec, lanes: list[int], length: float, end: bool) -> None:
    """Lanes (positions) that end (begin) in this section narrow to (widen from) nothing over
    ``length`` m at its end (start): the leftmost lane's left border moves onto its right one,
    any other lane's right border onto its left one (the road's edge moves, not its neighbours)."""
    for j in lanes:
        inner, outer = (1, 0) if j == 0 else (j, j + 1)
        si, ti = spec.borders[inner]
        so, to = spec.borders[outer]
        grid = np.union1d(si, so)
        ti_g, to_g = np.interp(grid, si, ti), np.interp(grid, so, to)
        if end:
            w = np.clip((spec.s1 - grid) / max(length, 1e-6), 0.0, 1.0)
        else:
            w = np.clip((grid - spec.s0) / max(length, 1e-6), 0.0, 1.0)
        spec.borders[outer] = (grid, ti_g + w * (to_g - ti_g))
        spec.borders[inner] = (grid, ti_g)


def _junctions(flow, px, py, ph, pt, ptm, cw, o: BuildOptions, new_id):
    """One connecting road per turning movement (see the module doc)."""
    from aveas_format.opendrive.network import RoadNetwork
    from aveas_format.opendrive.model import Header

    comp = flow.carriageway
    junc = flow.junction
    # per track, its points' carriageway / junction in time order (points are in (track, time) order)
    label = np.where(comp >= 0, comp, np.where(junc >= 0, -2 - junc, -1))
    movements: dict[tuple[int, int, int], list[tuple[int, int]]] = {}
    n = len(label)
    # runs of equal labels per track
    brk = np.r_[0, np.flatnonzero((label[1:] != label[:-1]) | (pt[1:] != pt[:-1])) + 1]
    run_lab = label[brk]
    run_trk = pt[brk]
    run_end = np.r_[brk[1:], n]
    for k in range(1, len(brk) - 1):
        if run_lab[k] <= -2 and run_trk[k - 1] == run_trk[k] == run_trk[k + 1]:
            a, b = int(run_lab[k - 1]), int(run_lab[k + 1])
            if a >= 0 and b >= 0 and a != b and a in cw and b in cw:
                movements.setdefault((a, b, -2 - int(run_lab[k])), []).append((run_end[k - 1] - 1, brk[k + 1]))
    nets = {c: RoadNetwork(Header(), {d["road"].id: d["road"]}, {}) for c, d in cw.items()}
    junctions: dict[int, Junction] = {}
    roads = []
    for (a, b, j), pairs in sorted(movements.items()):
        tracks = {int(pt[i]) for i, _ in pairs}
        if len(tracks) < o.min_tracks:
            continue
        A, B = cw[a], cw[b]
        ra, rb = A["road"], B["road"]
        la, pa, ha, wa = _lane_at(nets[a], ra, ra.length, px[[i for i, _ in pairs]], py[[i for i, _ in pairs]], A["frame"])
        lb, pb, hb, wb = _lane_at(nets[b], rb, 0.0, px[[k for _, k in pairs]], py[[k for _, k in pairs]], B["frame"])
        if la is None or lb is None:
            continue
        # the median path between: each track's points from leaving A to entering B, by share of length
        paths = []
        for i, k in pairs[:200]:
            seg = np.column_stack([px[i:k + 1], py[i:k + 1]])
            if len(seg) >= 2:
                cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(seg, axis=0).T))]
                if cum[-1] > 0:
                    u = np.linspace(0.0, cum[-1], 21)
                    paths.append(np.column_stack([np.interp(u, cum, seg[:, 0]), np.interp(u, cum, seg[:, 1])]))
        mid = np.median(np.array(paths), axis=0) if paths else np.array([pa, pb])
        # only what lies beyond the end of the lane left and before the start of the lane entered
        da, db = np.array([math.cos(ha), math.sin(ha)]), np.array([math.cos(hb), math.sin(hb)])
        inside = ((mid - pa) @ da > 1.0) & ((pb - mid) @ db > 1.0)
        pts = np.vstack([pa, mid[inside], pb])
        try:
            geoms = hermite_chain(pts, start_heading=ha, end_heading=hb, tol=max(o.reference_tol, 0.25),
                                  smooth=max(3.0, o.step))
        except ValueError:
            continue
        L = float(sum(g.length for g in geoms))
        ss = np.linspace(0.0, L, 9)
        w = wa + (wb - wa) * (3 * (ss / L) ** 2 - 2 * (ss / L) ** 3)
        spec = SectionSpec(0.0, L, [(ss, w / 2), (ss, -w / 2)], 0, [LaneSpec("driving")])
        offset, secs = lane_sections([spec], o.tol)
        jid = str(1000 + j)
        rid = new_id()
        road = Road(id=rid, length=L, junction=jid, types=[RoadType(0.0, "unknown")], geometries=geoms,
                    lane_offset=offset, lane_sections=secs,
                    predecessor=RoadLink("road", ra.id, "end"), successor=RoadLink("road", rb.id, "start"))
        lane = secs[0].lane(-1)
        lane.predecessors, lane.successors = [la], [lb]
        roads.append(road)
        jn = junctions.setdefault(j, Junction(jid))
        jn.connections.append(Connection(str(len(jn.connections)), ra.id, rid, contact_point="start",
                                         lane_links=[LaneLink(la, -1)]))
        ra.successor = RoadLink("junction", jid)
        rb.predecessor = RoadLink("junction", jid)
    return [junctions[k] for k in sorted(junctions)], roads


def _lane_at(net, road: Road, s: float, x: np.ndarray, y: np.ndarray, frame: Frame):
    """The lane at road end ``s`` that most of the points (x, y) near it are in: (lane id, its
    centre point there, the road heading there, its width)."""
    sp, tp = frame.project(x, y)
    sec = road.lane_sections[0 if s == 0.0 else -1]
    ids = [ln.id for ln in sec.right]
    if not ids:
        return None, None, None, None
    best, votes = None, -1
    for lid in ids:
        inner, outer = net.lane_borders(road.id, np.full(len(tp), s), np.full(len(tp), lid))
        hit = int(((tp <= inner) & (tp >= outer)).sum())
        if hit > votes:
            best, votes = lid, hit
    if votes <= 0:  # none inside a lane: the nearest lane centre to the mean offset
        cen = []
        for lid in ids:
            inner, outer = net.lane_borders(road.id, [s], [lid])
            cen.append(abs(0.5 * (inner[0] + outer[0]) - float(np.median(tp))))
        best = ids[int(np.argmin(cen))]
    inner, outer = net.lane_borders(road.id, [s], [best])
    tc, w = 0.5 * float(inner[0] + outer[0]), abs(float(inner[0] - outer[0]))
    xx, yy, _, hh = net.road_to_world(road.id, [s], [tc])
    return best, np.array([xx[0], yy[0]]), float(hh[0]), w


# -- 5. the report ------------------------------------------------------------------------------------
def fit_report(net, x, y, heading, *, sample: int = 300_000, seed: int = 0) -> dict[str, Any]:
    """How well the map fits the points: their share on a lane and, per road and lane, the count,
    RMS and p95 of their distance from the lane centre (``lane_offset``)."""
    rng = np.random.default_rng(seed)
    idx = np.arange(len(x)) if len(x) <= sample else np.sort(rng.choice(len(x), sample, replace=False))
    pr = net.world_to_road(x[idx], y[idx], heading[idx], drivable_only=True)
    on = pr.n_candidates > 0
    lanes = []
    if on.any():
        keys = np.array([f"{r}|{l}" for r, l in zip(pr.road_id[on], pr.lane_id[on])])
        off = np.abs(pr.lane_offset[on])
        uniq, inv = np.unique(keys, return_inverse=True)
        for k, key in enumerate(uniq):
            d = off[inv == k]
            rid, lid = key.split("|")
            lanes.append({"road_id": rid, "lane_id": int(lid), "points": int(len(d)),
                          "rms_m": round(float(np.sqrt(np.mean(d * d))), 4),
                          "p95_m": round(float(np.percentile(d, 95)), 4)})
    all_off = np.abs(pr.lane_offset[on])
    return {"points_checked": int(len(idx)), "on_lane_share": round(float(on.mean()), 4),
            "lateral_rms_m": round(float(np.sqrt(np.mean(all_off ** 2))), 4) if on.any() else None,
            "lateral_p95_m": round(float(np.percentile(all_off, 95)), 4) if on.any() else None,
            "per_lane": lanes}


__all__ = ["BuildOptions", "MapBuild", "fit_report", "lane_layout", "map_from_tracks", "motion", "reference_path"]
