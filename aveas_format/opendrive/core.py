"""The evaluated road network below the projection: ids, reference lines, profiles, lane borders.

:class:`NetworkCore` holds what :mod:`.projection`, :mod:`.polygons` and :mod:`.check` build on;
:class:`~aveas_format.opendrive.network.RoadNetwork` adds the spatial index, world -> road, the
lane polygons and the self-check on top (so none of those modules imports the network that uses
them). Its public attributes are the small internal API of the package: ``road_list``,
``road_ids``, ``road_index``, ``road_id_array`` (ids with a trailing None for "no road"),
``road_length``, ``road_rht``, ``road_in_junction``, ``drivable_code`` (per lane type code, a
trailing False), :meth:`~NetworkCore.road_index_of` and :meth:`~NetworkCore.linked`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .geometry import PlanView, Profile
from .lanes import DRIVABLE_TYPES, LaneTable
from .model import Header, Junction, Road


class NetworkCore:
    """The parsed map with its vectorised geometry and lanes (see the module doc).

    Attributes: ``header`` (:class:`~.model.Header`), ``roads`` (dict road id -> :class:`~.model.Road`),
    ``junctions`` (dict junction id -> :class:`~.model.Junction`), ``path`` (source file or None).

    Coordinates are those of the file (its local x/y frame; the header ``<offset>`` is *not*
    applied: ``aveas_format.crs`` maps them to the geoReference CRS). ``t`` is positive to the
    left of the reference line; lane ids are positive left, negative right, 0 the centre lane.
    Every method is vectorised over its array arguments.
    """

    def __init__(
        self, header: Header, roads: dict[str, Road], junctions: dict[str, Junction], path: str | None = None
    ) -> None:
        self.header = header
        self.roads = roads
        self.junctions = junctions
        self.path = path
        self.road_list = list(roads.values())
        self.road_ids = [r.id for r in self.road_list]
        self.road_index = {rid: i for i, rid in enumerate(self.road_ids)}
        self.road_id_array = np.array(self.road_ids + [None], dtype=object)
        self.road_length = np.array([r.length for r in self.road_list] + [0.0], dtype=np.float64)
        lengths = np.array([max(r.length, 0.0) for r in self.road_list])
        # disjoint "global s" ranges per road, used for vectorised record lookups
        self.road_offset = np.concatenate([[0.0], np.cumsum(lengths + 10.0)])[: len(lengths)]
        self.road_rht = np.array([r.rule.upper() != "LHT" for r in self.road_list], dtype=bool)
        self.road_in_junction = np.array([r.junction is not None for r in self.road_list], dtype=bool)
        self.plan = PlanView(self.road_list, self.road_offset)
        self.elevation = Profile([r.elevation for r in self.road_list], self.road_offset)
        self.superelevation = Profile([r.superelevation for r in self.road_list], self.road_offset)
        self.lane_offset = Profile([r.lane_offset for r in self.road_list], self.road_offset)
        self.lanes = LaneTable(self.road_list, self.road_offset)
        self.drivable_code = np.array([t in DRIVABLE_TYPES for t in self.lanes.types] + [False], dtype=bool)
        self.links = self._build_links()

    def __repr__(self) -> str:
        src = f"{self.path} " if self.path else ""
        return f"<RoadNetwork {src}OpenDRIVE {self.header.version}: {len(self.roads)} roads, {len(self.junctions)} junctions>"

    # -- ids -----------------------------------------------------------------------------------
    def road_index_of(self, road_id: Any) -> np.ndarray:
        """Road indices for a road id or an array of them (KeyError naming an unknown id)."""
        if isinstance(road_id, (str, int, np.integer)):
            rid = str(road_id)
            if rid not in self.road_index:
                raise KeyError(f"no road {rid!r} in the map")
            return np.array(self.road_index[rid], dtype=np.int64)
        arr = np.asarray(road_id, dtype=object).ravel()
        if arr.size == 0:
            return np.zeros(0, dtype=np.int64)
        import pyarrow as pa

        try:  # (texts, the common case: each distinct one looked up once, hashed, not sorted)
            enc = pa.array(arr, pa.string()).dictionary_encode()
            uniq, inv = enc.dictionary.to_pylist(), enc.indices.to_numpy(zero_copy_only=False)
            if enc.indices.null_count:
                raise ValueError("null road ids")
        except (ValueError, TypeError):  # (ids that are no texts, None: as texts)
            uniq, inv = np.unique(arr.astype(str), return_inverse=True)
        missing = sorted(u for u in uniq if u not in self.road_index)
        if missing:
            raise KeyError(f"no road {missing[0]!r} in the map")
        return np.array([self.road_index[u] for u in uniq], dtype=np.int64)[inv]

    def _broadcast(self, road_id: Any, *arrays: Any) -> tuple[np.ndarray, ...]:
        ri = self.road_index_of(road_id)
        arrs = [np.asarray(a, dtype=np.float64) for a in arrays]
        out = np.broadcast_arrays(ri, *arrs)
        return tuple(np.ravel(np.array(o)) for o in out)

    # -- geometry ----------------------------------------------------------------------------------
    def reference_line(self, road_id: Any, s: Any):
        """``(x, y, hdg, curvature)`` of the reference line at ``s`` (arrays)."""
        r, s = self._broadcast(road_id, s)
        x, y, h, k, _, _ = self.plan.at(r, s)
        return x, y, h, k

    def road_to_world(self, road_id: Any, s: Any, t: Any, h: Any = None):
        """``(x, y, z, heading)`` of road coordinates; heading is the road heading at s.

        ``z = elevation(s) + t * tan(superelevation(s)) + h`` (lane heights and road shapes are
        not applied; x, y take t as a horizontal offset).
        """
        r, s, t = self._broadcast(road_id, s, t)
        x, y, hdg, _, _, _ = self.plan.at(r, s)
        x = x - t * np.sin(hdg)
        y = y + t * np.cos(hdg)
        z = self.elevation(r, s) + t * np.tan(self.superelevation(r, s))
        if h is not None:
            z = z + np.broadcast_to(np.asarray(h, dtype=np.float64), z.shape)
        return x, y, z, hdg

    def lane_at(self, road_id: Any, s: Any, t: Any):
        """``(lane_id int16, lane_offset)``: the lane containing t at s (0 / NaN off the road)."""
        r, s, t = self._broadcast(road_id, s, t)
        sc = np.clip(s, 0.0, self.road_length[r])
        b = self.lanes.borders(self.lanes.find_piece(r, sc), sc)
        lane_id, off, _, _, _ = self.lanes.locate(b, t)
        return lane_id, off

    def _sides(self, r: np.ndarray, s: np.ndarray):
        """The lanes of roads ``r`` at ``s`` (broadcast), per side: ``(side, ids, type codes, inner
        borders, outer borders)`` (n x lanes of the piece), and the centre line's t."""
        sc = np.clip(s, 0.0, self.road_length[r])
        piece = self.lanes.find_piece(r, sc)
        b = self.lanes.borders(piece, sc)
        sides = [(side, ids[piece], types[piece], np.concatenate([b.center[:, None], outers[:, :-1]], axis=1),
                  outers) for side, outers, ids, types in (("left", b.left, self.lanes.lid, self.lanes.ltype),
                                                           ("right", b.right, self.lanes.rid, self.lanes.rtype))]
        return sides, b.center

    def lane_borders(self, road_id: Any, s: Any, lane_id: Any):
        """``(inner_t, outer_t)`` of lane ``lane_id`` at s (NaN where the lane does not exist)."""
        r, s, lid = self._broadcast(road_id, s, lane_id)
        return self._borders_of(*self._sides(r, s), lid)

    @staticmethod
    def _borders_of(sides: list, center: np.ndarray, lid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`lane_borders` of lanes ``lid`` from :meth:`_sides`."""
        lid = lid.astype(np.int64)
        inner = np.full(len(lid), np.nan)
        outer = np.full(len(lid), np.nan)
        for _, ids, _, inners, outers in sides:
            match = ids == lid[:, None]
            rows = np.flatnonzero(match.any(1))
            k = np.argmax(match[rows], axis=1)
            inner[rows] = inners[rows, k]
            outer[rows] = outers[rows, k]
        zero = lid == 0
        inner[zero] = outer[zero] = center[zero]
        return inner, outer

    def lane_counts(self, road_id: Any, s: Any, lane_id: Any = None) -> dict[str, np.ndarray]:
        """The lanes beside the centre lane at s, per side: ``left``/``right`` those present
        (wider than 1 cm), ``left_drivable``/``right_drivable`` those of them of a drivable type;
        with ``lane_id`` also that lane's ``inner``/``outer`` borders (:meth:`lane_borders`, the
        lanes read once for both)."""
        if lane_id is not None:
            r, s, lid = self._broadcast(road_id, s, lane_id)
        else:
            (r, s), lid = self._broadcast(road_id, s), None
        sides, center = self._sides(r, s)
        out = {} if lid is None else dict(zip(("inner", "outer"), self._borders_of(sides, center, lid)))
        for side, ids, types, inners, outers in sides:
            present = (ids != 0) & (np.abs(outers - inners) > 0.01)
            out[side] = present.sum(1)
            out[f"{side}_drivable"] = (present & (types >= 0) & self.drivable_code[np.where(types >= 0, types, 0)]).sum(1)
        return out

    def lane_type(self, road_id: Any, s: Any, lane_id: Any) -> np.ndarray:
        """The ``type`` of lane ``lane_id`` at s (object array; None where the lane does not exist
        there), vectorised over road ids, s and lane ids."""
        r, s, lid = self._broadcast(road_id, s, lane_id)
        sc = np.clip(s, 0.0, self.road_length[r])
        piece = self.lanes.find_piece(r, sc)
        lid = lid.astype(np.int64)[:, None]
        codes = np.full(len(s), -1, dtype=np.int64)
        for ids, types in ((self.lanes.lid, self.lanes.ltype), (self.lanes.rid, self.lanes.rtype)):
            m = (ids[piece] == lid) & (lid != 0)
            has = m.any(1)
            k = np.argmax(m, 1)
            codes[has] = types[piece[has], k[has]]
        names = np.array(list(self.lanes.types) + [None], dtype=object)
        return names[np.where(codes >= 0, codes, len(self.lanes.types))]

    def _build_links(self) -> np.ndarray:
        """Sorted int64 keys ``a * R + b`` of directly connected road pairs (both directions)."""
        R = len(self.road_list)
        pairs: set[tuple[int, int]] = set()
        idx = self.road_index
        by_junction_incoming: dict[tuple[str, str], list[str]] = {}
        for j in self.junctions.values():
            for c in j.connections:
                tgt = c.target_road
                if c.incoming_road in idx and tgt in idx:
                    pairs.add((idx[c.incoming_road], idx[tgt]))
                    by_junction_incoming.setdefault((j.id, c.incoming_road), []).append(tgt)
        for r in self.road_list:
            for link in (r.predecessor, r.successor):
                if link is None:
                    continue
                if link.element_type == "road" and link.element_id in idx:
                    pairs.add((idx[r.id], idx[link.element_id]))
                elif link.element_type == "junction":
                    for tgt in by_junction_incoming.get((link.element_id, r.id), []):
                        pairs.add((idx[r.id], idx[tgt]))
        keys = [a * R + b for a, b in pairs] + [b * R + a for a, b in pairs]
        return np.unique(np.array(keys, dtype=np.int64))

    def linked(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """True where roads a and b are directly connected (False where b < 0)."""
        R = len(self.road_list)
        key = a * R + np.maximum(b, 0)
        if len(self.links) == 0:
            return np.zeros(len(a), dtype=bool)
        pos = np.clip(np.searchsorted(self.links, key), 0, len(self.links) - 1)
        return (self.links[pos] == key) & (b >= 0)

    # -- sampling (tests, benchmarks) ---------------------------------------------------------------
    def sample_lane_points(
        self, n: int, seed: int = 0, drivable_only: bool = True, margin: float = 0.05
    ) -> dict[str, np.ndarray]:
        """``n`` random road positions inside lanes: dict of ``road_id``, ``road``, ``s``, ``t``,
        ``lane_id``. Roads are drawn in proportion to their length, lanes uniformly among those
        present (non-empty, drivable if asked) at s, t uniformly across the lane's inner part."""
        rng = np.random.default_rng(seed)
        L = self.road_length[:-1]
        prob = L / L.sum()
        out_r, out_s, out_t, out_l = [], [], [], []
        need = n
        while need > 0:
            m = max(2 * need, 1024)
            r = rng.choice(len(L), size=m, p=prob)
            s = rng.uniform(0, 1, m) * L[r]
            piece = self.lanes.find_piece(r, s)
            b = self.lanes.borders(piece, s)
            cand_t = []
            cand_ok = []
            cand_id = []
            for outers, ids, types in (
                (b.left, self.lanes.lid[piece], self.lanes.ltype[piece]),
                (b.right, self.lanes.rid[piece], self.lanes.rtype[piece]),
            ):
                inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
                width = np.abs(outers - inners)
                ok = (ids != 0) & (width > 0.2)
                if drivable_only:
                    ok &= self.drivable_code[np.where(types >= 0, types, -1)] & (types >= 0)
                u = rng.uniform(margin, 1 - margin, ok.shape)
                cand_t.append(inners + u * (outers - inners))
                cand_ok.append(ok)
                cand_id.append(ids)
            T = np.concatenate(cand_t, 1)
            OK = np.concatenate(cand_ok, 1)
            ID = np.concatenate(cand_id, 1)
            cnt = OK.sum(1)
            has = cnt > 0
            pick = np.floor(rng.uniform(0, 1, m) * np.maximum(cnt, 1)).astype(np.int64)
            # the pick-th True column of each row
            cum = np.cumsum(OK, 1) - 1
            col = np.argmax((cum == pick[:, None]) & OK, axis=1)
            rows = np.flatnonzero(has)[:need]
            out_r.append(r[rows])
            out_s.append(s[rows])
            out_t.append(T[rows, col[rows]])
            out_l.append(ID[rows, col[rows]])
            need -= len(rows)
        r = np.concatenate(out_r)
        return {
            "road": r,
            "road_id": self.road_id_array[r],
            "s": np.concatenate(out_s),
            "t": np.concatenate(out_t),
            "lane_id": np.concatenate(out_l).astype(np.int16),
        }


__all__ = ["NetworkCore"]
