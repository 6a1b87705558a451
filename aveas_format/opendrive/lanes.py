"""Lane borders t(s) of a whole network, vectorised.

Every road's lane sections are cut into *pieces*: intervals of s in which the lane offset and every
lane's width (or border) is one cubic. A piece stores, per side, one padded row of slots ordered
from the centre lane outwards (left: 1, 2, 3 ...; right: -1, -2, -3 ...), each with its cubic's
coefficients and start s. Evaluating the borders of many points then is a lookup of the piece
(``searchsorted``) and one cubic per slot.

Conventions: ``t`` is positive to the left. The centre lane lies at ``laneOffset(s)``. A lane with
``<width>`` records has its outer border at the inner border +/- width; a lane that has only
``<border>`` records has its outer border at ``t = border(ds)`` measured from the road's reference
line (ASAM OpenDRIVE 1.8.1, 11.6.2; where a lane has both, the widths win as the standard says).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import SegmentedIndex, polyval3
from .model import Lane, Road

#: Lane types on which vehicles drive (ASAM OpenDRIVE lane types).
DRIVABLE_TYPES = frozenset(
    {
        "driving",
        "entry",
        "exit",
        "onRamp",
        "offRamp",
        "connectingRamp",
        "slipLane",
        "bidirectional",
        "mwyEntry",
        "mwyExit",
        "special1",
        "special2",
        "special3",
        "roadWorks",
        "tram",
        "bus",
        "taxi",
        "HOV",
    }
)


@dataclass
class Borders:
    """Borders of many points: centre ``(N,)``, left and right outer borders ``(N, K)``."""

    center: np.ndarray
    left: np.ndarray
    right: np.ndarray
    piece: np.ndarray


def shift_poly(coef: np.ndarray, delta: float) -> np.ndarray:
    """Coefficients of ``p(x + delta)`` for the cubic ``p`` (Taylor shift)."""
    a, b, c, d = coef
    return np.array(
        [
            a + delta * (b + delta * (c + delta * d)),
            b + delta * (2 * c + 3 * delta * d),
            c + 3 * delta * d,
            d,
        ]
    )


def _record_at(table: np.ndarray, sec_s: float, s: float) -> tuple[np.ndarray, float] | None:
    """The width/border record (a, b, c, d) valid at absolute ``s`` and its absolute start."""
    if len(table) == 0:
        return None
    starts = sec_s + table[:, 0]
    i = max(0, int(np.searchsorted(starts, s + 1e-12, side="right")) - 1)
    return table[i, 1:5], float(starts[i])


class LaneTable:
    """Padded per-piece lane tables for all roads (see the module doc)."""

    def __init__(self, roads: list[Road], road_offset: np.ndarray) -> None:
        self.road_offset = road_offset
        self.kl = max([len(sec.left) for r in roads for sec in r.lane_sections] + [1])
        self.kr = max([len(sec.right) for r in roads for sec in r.lane_sections] + [1])
        self.types: list[str] = []
        type_code: dict[str, int] = {}

        def code(t: str) -> int:
            if t not in type_code:
                type_code[t] = len(self.types)
                self.types.append(t)
            return type_code[t]

        rows_piece = []  # (road, section_global, s_start)
        ccoef, lb, rb, lid, ltyp, rid, rtyp, has_border = [], [], [], [], [], [], [], []
        sec_road, sec_local, sec_start, sec_end, sec_first_piece, sec_npieces = [], [], [], [], [], []
        piece_starts_per_road = []
        for ri, road in enumerate(roads):
            starts_this_road = []
            lo_starts = np.array([r.s for r in road.lane_offset])
            lo_coef = [np.array(r.coef) for r in road.lane_offset]
            nsec = len(road.lane_sections)
            for si, sec in enumerate(road.lane_sections):
                s_a = sec.s
                # a section ends where the next one starts, at the latest at the road's end; a
                # section that starts where the next one does (two <laneSection s="0">) or at/after
                # the road's end has zero length: its pieces exist (check reports it), but the
                # lookup of "the last piece starting at or before s" passes over it
                s_next = road.lane_sections[si + 1].s if si + 1 < nsec else road.length
                s_b = max(s_a, min(s_next, road.length))
                cuts = {s_a}
                for lane in sec.left + sec.right:
                    tab = lane.widths if len(lane.widths) else lane.borders
                    cuts.update(float(x) for x in s_a + tab[:, 0])
                cuts.update(float(x) for x in lo_starts)
                cuts = sorted(c for c in cuts if s_a <= c < s_b or c == s_a)
                sec_road.append(ri)
                sec_local.append(si)
                sec_start.append(s_a)
                sec_end.append(s_b)
                sec_first_piece.append(len(rows_piece))
                sec_npieces.append(len(cuts))
                gsec = len(sec_road) - 1
                for c in cuts:
                    rows_piece.append((ri, gsec, c))
                    starts_this_road.append(c)
                    # centre lane: the laneOffset record active at c, expanded about c
                    if len(lo_starts):
                        j = max(0, int(np.searchsorted(lo_starts, c + 1e-12, side="right")) - 1)
                        center = shift_poly(lo_coef[j], c - lo_starts[j])
                    else:
                        center = np.zeros(4)
                    ccoef.append(center)
                    border_here = False
                    for side, k, out_b, out_id, out_t, sign in (
                        (sec.left, self.kl, lb, lid, ltyp, 1.0),
                        (sec.right, self.kr, rb, rid, rtyp, -1.0),
                    ):
                        coef = np.zeros((k, 4))
                        ids = np.zeros(k, dtype=np.int16)
                        typ = np.full(k, -1, dtype=np.int16)
                        prev = center
                        for j in range(k):
                            if j < len(side):
                                lane = side[j]
                                ids[j] = lane.id
                                typ[j] = code(lane.type)
                                rec = self._lane_record(lane, s_a, c)
                                if rec is not None:
                                    poly, s0, is_border = rec
                                    local = shift_poly(np.asarray(poly, dtype=np.float64), c - s0)
                                    prev = local if is_border else prev + sign * local
                                    border_here |= is_border
                            coef[j] = prev
                        out_b.append(coef)
                        out_id.append(ids)
                        out_t.append(typ)
                    has_border.append(border_here)
            piece_starts_per_road.append(np.array(starts_this_road, dtype=np.float64))
        self.piece_road = np.array([r[0] for r in rows_piece], dtype=np.int64)
        self.piece_section = np.array([r[1] for r in rows_piece], dtype=np.int64)
        self.piece_start = np.array([r[2] for r in rows_piece], dtype=np.float64)
        self.index = SegmentedIndex.build(piece_starts_per_road, road_offset)
        #: per piece: centre-lane cubic (P, 4) and outer-border cubics per slot (P, K, 4), all in
        #: ds = s - piece_start; padded slots repeat the last lane's border (zero width)
        self.ccoef = np.array(ccoef).reshape(-1, 4)
        self.lbcoef = np.array(lb).reshape(-1, self.kl, 4)
        self.rbcoef = np.array(rb).reshape(-1, self.kr, 4)
        self.lid, self.ltype = np.array(lid).reshape(-1, self.kl), np.array(ltyp).reshape(-1, self.kl)
        self.rid, self.rtype = np.array(rid).reshape(-1, self.kr), np.array(rtyp).reshape(-1, self.kr)
        self.piece_has_border = np.array(has_border, dtype=bool)
        self.nleft = (self.lid != 0).sum(1)
        self.nright = (self.rid != 0).sum(1)
        self.section_road = np.array(sec_road, dtype=np.int64)
        self.section_local = np.array(sec_local, dtype=np.int64)
        self.section_start = np.array(sec_start)
        self.section_end = np.array(sec_end)
        self.section_first_piece = np.array(sec_first_piece, dtype=np.int64)
        self.section_npieces = np.array(sec_npieces, dtype=np.int64)
        # a lookup that lands on a piece of a zero-length section (one starting at the road's end)
        # uses the last piece before it on the same road instead, where there is one
        empty = (self.section_end <= self.section_start)[self.piece_section]
        last_used = np.where(empty, -1, np.arange(len(empty)))
        last_used = np.maximum.accumulate(last_used) if len(empty) else last_used
        ok = (last_used >= 0) & (self.piece_road[np.maximum(last_used, 0)] == self.piece_road)
        self._piece_used = np.where(empty & ok, last_used, np.arange(len(empty)))

    @staticmethod
    def _lane_record(lane: Lane, sec_s: float, s: float):
        if len(lane.widths):
            rec = _record_at(lane.widths, sec_s, s)
            return (rec[0], rec[1], False) if rec else None
        if len(lane.borders):
            rec = _record_at(lane.borders, sec_s, s)
            return (rec[0], rec[1], True) if rec else None
        return None

    # ------------------------------------------------------------------------------------------
    def find_piece(self, road: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The piece in effect at (road, s): the last one starting at or before s, passing over
        zero-length sections."""
        return self._piece_used[self.index.find(road, s, self.road_offset)]

    def pieces_in_section(self, gsec: int, s: np.ndarray) -> np.ndarray:
        """Piece of section ``gsec`` for each s (clamped to the section's own pieces)."""
        first = self.section_first_piece[gsec]
        n = self.section_npieces[gsec]
        starts = self.piece_start[first : first + n]
        k = np.searchsorted(starts, s, side="right") - 1
        return first + np.clip(k, 0, n - 1)

    def borders(self, piece: np.ndarray, s: np.ndarray) -> Borders:
        """Centre-lane t and the outer border t of every lane slot at (piece, s)."""
        ds = s - self.piece_start[piece]
        center = polyval3(self.ccoef[piece], ds)
        d2 = ds[:, None]
        left = polyval3(self.lbcoef[piece], d2)
        right = polyval3(self.rbcoef[piece], d2)
        return Borders(center=center, left=left, right=right, piece=piece)

    def extent(self, b: Borders) -> tuple[np.ndarray, np.ndarray]:
        """Leftmost and rightmost t of the road surface (over all lanes) for borders ``b``."""
        tl = np.max(np.concatenate([b.center[:, None], b.left], axis=1), axis=1)
        tr = np.min(np.concatenate([b.center[:, None], b.right], axis=1), axis=1)
        return tl, tr

    def locate(self, b: Borders, t: np.ndarray, tol: float = 1e-6):
        """Lane containing t: ``(lane_id int16, lane_offset, inner_t, outer_t, type_code)``.

        ``lane_id`` is 0 and ``lane_offset`` NaN where t lies outside every lane (beyond ``tol``).
        A point on the border between two lanes belongs to the outer one; on the centre line to
        the left lane 1 where it exists.
        """
        p = b.piece
        n = len(t)
        lane_id = np.zeros(n, dtype=np.int16)
        inner_t = np.full(n, np.nan)
        outer_t = np.full(n, np.nan)
        ltype = np.full(n, -1, dtype=np.int16)
        # fast path for ordered borders: the lane is the number of outer borders passed
        nl, nr = self.nleft[p], self.nright[p]
        rows = np.arange(n)
        is_left = (t >= b.center) & (nl > 0)
        kl = np.minimum(((b.left <= t[:, None]) & (self.lid[p] != 0)).sum(1), self.kl - 1)
        kr = np.minimum(((b.right >= t[:, None]) & (self.rid[p] != 0)).sum(1), self.kr - 1)
        in_l = np.where(kl > 0, b.left[rows, np.maximum(kl - 1, 0)], b.center)
        out_l = b.left[rows, kl]
        in_r = np.where(kr > 0, b.right[rows, np.maximum(kr - 1, 0)], b.center)
        out_r = b.right[rows, kr]
        ok_l = is_left & (kl < nl) & (in_l <= t) & (t < out_l)
        ok_r = ~is_left & (kr < nr) & (out_r < t) & (t <= in_r)
        for ok, k, ids, types, inn, out in (
            (ok_l, kl, self.lid, self.ltype, in_l, out_l),
            (ok_r, kr, self.rid, self.rtype, in_r, out_r),
        ):
            r = np.flatnonzero(ok)
            lane_id[r] = ids[p[r], k[r]]
            ltype[r] = types[p[r], k[r]]
            inner_t[r] = inn[r]
            outer_t[r] = out[r]
        # the rest (unordered borders, points on the road edge within tol, off-road points)
        tl, tr = self.extent(b)
        rest = np.flatnonzero((lane_id == 0) & (t <= tl + tol) & (t >= tr - tol))
        if len(rest):
            sub = Borders(center=b.center[rest], left=b.left[rest], right=b.right[rest], piece=p[rest])
            li, _, inn, out, ty = self._locate_general(sub, t[rest], tol)
            lane_id[rest], inner_t[rest], outer_t[rest], ltype[rest] = li, inn, out, ty
        centre = (inner_t + outer_t) / 2
        lane_offset = np.where(lane_id != 0, t - centre, np.nan)
        return lane_id, lane_offset, inner_t, outer_t, ltype

    def _locate_general(self, b: Borders, t: np.ndarray, tol: float):
        """:meth:`locate` for any border order (negative widths, crossing borders)."""
        p = b.piece
        n = len(t)
        lane_id = np.zeros(n, dtype=np.int16)
        inner_t = np.full(n, np.nan)
        outer_t = np.full(n, np.nan)
        ltype = np.full(n, -1, dtype=np.int16)
        tt = t[:, None]
        sides = []
        for outers, ids, types, sign in (
            (b.left, self.lid[p], self.ltype[p], 1.0),
            (b.right, self.rid[p], self.rtype[p], -1.0),
        ):
            inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
            lo = np.minimum(inners, outers)
            hi = np.maximum(inners, outers)
            valid = ids != 0
            strict = ((tt >= lo) & (tt < hi) if sign > 0 else (tt > lo) & (tt <= hi)) & valid
            # tolerance: a point just outside a non-empty lane (e.g. on the road's outer edge)
            loose = (tt >= lo - tol) & (tt <= hi + tol) & valid & (hi > lo)
            sides.append((strict, inners, outers, ids, types))
            sides.append((loose, inners, outers, ids, types))
        # strict hits first (left, then right), then the tolerant ones
        for hit, inners, outers, ids, types in (sides[0], sides[2], sides[1], sides[3]):
            rows = np.flatnonzero(hit.any(1) & (lane_id == 0))
            if len(rows) == 0:
                continue
            kk = np.argmax(hit[rows], axis=1)
            lane_id[rows] = ids[rows, kk]
            inner_t[rows] = inners[rows, kk]
            outer_t[rows] = outers[rows, kk]
            ltype[rows] = types[rows, kk]
        return lane_id, None, inner_t, outer_t, ltype


__all__ = ["DRIVABLE_TYPES", "Borders", "LaneTable"]
