"""Whether a recording's positions are on its map: the one test of every import and the validator.

Vehicles belong on roads: a recording is *mostly off its map* where more than
:data:`OFF_MAP_SHARE` of its vehicles' states are on no road (their road coordinates null),
counted from :data:`OFF_MAP_MIN_STATES` states on. A recording without vehicles (pedestrians walk
beside the roads) is off its map where that share of its states is farther than
:data:`OFF_MAP_WALK_M` from every lane. The positions are then not in the map's frame: a map of
another site, the wrong CRS, the map header's ``<offset>``, x/y swapped, another unit, a
left-handed frame. :func:`off_road_causes` tries the cheap explanations on a sample of the
off-road positions and says which would put them on the map.

Every import is tested once, after it (:func:`aveas_format.converters.registry.convert`: one
:class:`OffMapWarning` with the share and the converter's hint), and ``validate`` reports the
same test as the rule ``map.mostly_off_road`` (its ``[map]`` thresholds default to the constants
here).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: mostly off the map: more than this share of the vehicles' states on no road
OFF_MAP_SHARE = 0.5
#: the test applies from this many states on
OFF_MAP_MIN_STATES = 10
#: without vehicles: off the map means farther than this (m) from every road surface
OFF_MAP_WALK_M = 30.0
#: off-road positions kept to try the likely causes on
SAMPLE = 2000


class OffMapWarning(UserWarning):
    """An import's positions are mostly on no road of its map (module doc)."""


@dataclass(frozen=True)
class OffMap:
    """A recording mostly off its map: ``off`` of ``n`` states of ``who`` (``vehicle`` or
    ``participant``) on no road, and the cheap explanations that would put them on it."""

    n: int
    off: int
    who: str
    causes: list[str]

    @property
    def share(self) -> float:
        """The share of the states off the map, 0..1."""
        return self.off / self.n if self.n else 0.0

    def message(self) -> str:
        """``60 of 60 vehicle states (100.0 %) are on no road of the map: likely ...``."""
        return (f"{self.off} of {self.n} {self.who + ' ' if self.who else ''}states "
                f"({100.0 * self.share:.1f} %) are on no "
                "road of the map: likely a map of another site, the wrong CRS, the map header's "
                "<offset>, x/y swapped, another unit or a left-handed frame; of those tried "
                "(swapped axes, mm/cm/feet/km, the offset, y mirrored): "
                + ("; ".join(self.causes) if self.causes else "none puts the positions on the map"))


def sample(idx: np.ndarray, k: int = SAMPLE) -> np.ndarray:
    """At most ``k`` of the indices ``idx``, evenly spaced."""
    if len(idx) > k:
        idx = idx[np.linspace(0, len(idx) - 1, k).astype(np.int64)]
    return idx


def off_road_counts(on_road: np.ndarray, x: np.ndarray, y: np.ndarray, vehicle: np.ndarray | None
                    ) -> tuple[int, int, np.ndarray]:
    """``(states, states on no road, a sample of their x/y)`` of the states where ``vehicle``
    (None: of every state)."""
    ok = np.isfinite(x) & np.isfinite(y)
    if vehicle is not None:
        ok &= vehicle
    off = ok & ~np.asarray(on_road, bool)
    idx = sample(np.flatnonzero(off))
    return int(ok.sum()), int(off.sum()), np.c_[x[idx], y[idx]]


def of_recording(rec) -> OffMap | None:
    """The :class:`OffMap` of a recording mostly off its map, else None: of its vehicles' states
    (of everyone's where it has no vehicle). A recording whose states are not loaded (written in
    parts) is read a row group at a time, four columns of it (bounded memory)."""
    import pyarrow.compute as pc

    from aveas_format.schema.taxonomy import VEHICLE_CLASSES

    parts = rec.participants
    is_vehicle = np.isin(np.asarray(parts["class"].to_pylist(), dtype=object), list(VEHICLE_CLASSES))
    cols = ["participant_id", "x", "y", "road_id"]
    if rec.states is not None:
        chunks = iter([rec.states.select(cols)]) if rec.states.num_rows else iter(())
    else:
        from aveas_format.io.reader import TableParts

        tp = TableParts(rec.path, rec.meta, "states")
        chunks = (tp.read(i, cols) for i in range(tp.num_row_groups))
    n = off = 0
    xys = []
    with_vehicles = bool(is_vehicle.any())
    for t in chunks:
        idx = pc.index_in(t["participant_id"], parts["participant_id"]).to_numpy(zero_copy_only=False)
        x, y = (t[c].to_numpy().astype(np.float64) for c in ("x", "y"))
        k, o, xy = off_road_counts(t["road_id"].is_valid().to_numpy(zero_copy_only=False), x, y,
                                   is_vehicle[idx] if with_vehicles else None)
        n, off = n + k, off + o
        xys.append(xy)
    if not n:
        return None
    xy = np.vstack(xys)
    return mostly_off(rec.map, n, off, xy[sample(np.arange(len(xy)))], with_vehicles)


def mostly_off(net, n: int, off: int, xy: np.ndarray, vehicles: bool, *,
               share: float = OFF_MAP_SHARE, min_states: int = OFF_MAP_MIN_STATES,
               walk_m: float = OFF_MAP_WALK_M) -> OffMap | None:
    """The :class:`OffMap` of ``off`` of ``n`` states on no road (``xy``: a sample of them) where
    the recording is mostly off the map ``net`` (module doc), else None."""
    if not vehicles and off and len(xy):
        # pedestrians and the like walk beside the roads: off the map means far from every lane
        # (estimated on the evenly spaced sample of the off-road states)
        far = far_from_lanes(net, xy, walk_m)
        off, xy = int(round(off * float(np.mean(far)))), xy[far]
    if n < min_states or off <= share * n:
        return None
    return OffMap(n, off, "vehicle" if vehicles else "participant",
                  off_road_causes(net, xy) if len(xy) else [])


def on_map_share(net, x: np.ndarray, y: np.ndarray) -> float:
    """The share of the points on a road of ``net``."""
    if not len(x):
        return 0.0
    return float(np.mean(net.world_to_road(x, y).on_road))


def far_from_lanes(net, xy: np.ndarray, dist_m: float) -> np.ndarray:
    """Which of the points ``xy`` are farther than ``dist_m`` from every road surface of ``net``
    (one bulk nearest-neighbour query on the map's own spatial index, the one ``world_to_road``
    uses: road chunks with their lanes' extent)."""
    import shapely

    index = net.spatial_index
    if not len(index.polygons):
        return np.ones(len(xy), dtype=bool)
    (i, _), d = index.tree.query_nearest(shapely.points(xy[:, 0], xy[:, 1]), return_distance=True,
                                         all_matches=False)
    far = np.ones(len(xy), dtype=bool)
    far[i] = d > dist_m
    return far


def off_road_causes(net, xy: np.ndarray) -> list[str]:
    """Which of the cheap explanations puts off-road positions ``xy`` on the map: swapped axes, a
    unit (mm, cm, feet, km), the map header's ``<offset>`` applied the wrong way, or y mirrored (a
    left-handed frame, as CARLA's); each as ``"with x and y swapped, 96% would be on a road"``,
    best first, those reaching 50 % (and still spread over at least 20 m and 5 % of the map's
    extent, where a unit shrinks them: shrinking every point onto one spot of a road explains
    nothing)."""
    x, y = xy[:, 0], xy[:, 1]
    tries: list[tuple[str, np.ndarray, np.ndarray]] = [
        ("with x and y swapped", y, x),
        ("with y negated (a left-handed frame, as CARLA's)", x, -y)]
    rescaled = {f"read as {unit}" for unit in ("millimetres", "centimetres", "feet")}
    for unit, f in (("millimetres", 1e-3), ("centimetres", 1e-2), ("feet", 0.3048),
                    ("kilometres", 1e3)):
        tries.append((f"read as {unit}", x * f, y * f))
    ox, oy, _, hdg = net.header.offset or (0.0, 0.0, 0.0, 0.0)
    if ox or oy or hdg:
        c, s_ = np.cos(hdg), np.sin(hdg)
        tries.append(("without the map's <offset> (positions in the projected CRS)",
                      (x - ox) * c + (y - oy) * s_, -(x - ox) * s_ + (y - oy) * c))
        tries.append(("with the map's <offset> added", x * c - y * s_ + ox, x * s_ + y * c + oy))
    xmin, ymin, xmax, ymax = net.bounds
    least = max(20.0, 0.05 * float(np.hypot(xmax - xmin, ymax - ymin)))
    found = []
    for what, tx, ty in tries:
        if what in rescaled and len(tx) > 1 and np.hypot(np.ptp(tx), np.ptp(ty)) < least:
            continue  # shrunk onto a spot of the map: no explanation
        share = on_map_share(net, tx, ty)
        if share >= 0.5:
            found.append((share, f"{what}, {share:.0%} would be on a road"))
    return [f for _, f in sorted(found, reverse=True)]
