"""Map: map.xodr readable and self-consistent, and the states' road coordinates consistent with it.

A missing map is structure.missing_file and a changed one structure.checksum. The rules here parse
the map with the OpenDRIVE engine (``aveas_format.opendrive``), report its self-check, and evaluate the
stored road coordinates of every state through it, vectorised per road (one call per road present,
never per row): (road_s, road_t) -> x/y, the lane borders at road_s, the lane type and direction.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, collector, rule
from aveas_format.validate.views import StatesView

_F = {"file": "states.parquet", "table": "states"}


@rule("map.unreadable", "error", "map.xodr cannot be parsed",
      "{file}:{line}: not a readable OpenDRIVE map: {error}",
      enforces="docs/format.md §1-2: map.xodr is the ASAM OpenDRIVE map every position refers to")
def unreadable(ctx: Context) -> Iterator[Hit]:
    """map.xodr is present but is not well-formed OpenDRIVE (broken XML, missing header, unknown
    geometry); nothing that refers to the map can be checked."""
    _ = ctx.network
    for p in [p for p in ctx.problems if p.kind == "map_unreadable"]:
        yield Hit(**p.fields)


def _checks(ctx: Context) -> list[Any]:
    if "map.checks" not in ctx.cache:
        net = ctx.network
        ctx.cache["map.checks"] = list(net.check()) if net is not None else []
    return ctx.cache["map.checks"]


def _check_hits(ctx: Context, severity: str) -> Iterator[Hit]:
    name = ctx.meta.map.file if ctx.meta is not None else "map.xodr"
    for f in _checks(ctx):
        if getattr(f, "severity", "error") == severity:
            yield Hit(file=name, line=f.line, road_id=f.road_id, check=f.code, detail=f.message)


@rule("map.opendrive_error", "error", "Map self-check: error",
      "{file}:{line}: {check}: {detail}",
      enforces="docs/format.md §2: map.xodr is a consistent ASAM OpenDRIVE map (links, lane widths, "
               "geoReference) that positions can refer to")
def opendrive_error(ctx: Context) -> Iterator[Hit]:
    """The OpenDRIVE engine's self-check (``RoadNetwork.check()``) finds an error: a link to a road,
    junction or lane that does not exist, a negative lane width, an unparseable geoReference. The
    check's own code is in ``context.check``."""
    yield from _check_hits(ctx, "error")


@rule("map.opendrive_warning", "warning", "Map self-check: warning",
      "{file}:{line}: {check}: {detail}",
      enforces=quality("map_quality"))
def opendrive_warning(ctx: Context) -> Iterator[Hit]:
    """The map self-check finds a warning: gaps or heading jumps between geometries, a road length
    that disagrees with its plan view, lanes folding over in tight curves, a geoReference that
    needs a lenient reading."""
    yield from _check_hits(ctx, "warning")


@rule("map.opendrive_info", "info", "Map self-check: note",
      "{file}:{line}: {check}: {detail}")
def opendrive_info(ctx: Context) -> Iterator[Hit]:
    """The map self-check has a note without quality impact (e.g. no ``<geoReference>``:
    recording.json ``crs`` alone defines the frame)."""
    yield from _check_hits(ctx, "info")


def road_eval(ctx: Context) -> dict[str, np.ndarray] | None:
    """The stored road coordinates of every (sorted) state evaluated through the map (cached)."""
    if "map.eval" in ctx.cache:
        return ctx.cache["map.eval"]
    out = None
    sv, net = ctx.states_view, ctx.network
    if sv is not None and net is not None:
        out = _evaluate(sv, net)
    ctx.cache["map.eval"] = out
    return out


def _evaluate(sv: StatesView, net) -> dict[str, np.ndarray] | None:
    rs = sv.strings("road_id")
    s, t, lane = sv.col("road_s"), sv.col("road_t"), sv.col("lane_id")
    if rs is None or s is None or t is None or lane is None:
        return None
    codes, values = rs
    n = sv.n
    e: dict[str, np.ndarray] = {
        "has_road": codes >= 0, "codes": codes, "values": values,
        "known": np.zeros(n, bool), "xw": np.full(n, np.nan), "yw": np.full(n, np.nan),
        "hdg": np.full(n, np.nan), "inner": np.full(n, np.nan), "outer": np.full(n, np.nan),
        "length": np.full(n, np.nan), "rht": np.ones(n, bool),
        "ltype": np.full(n, None, dtype=object), "s": s, "t": t, "lane": lane,
    }
    complete = (codes >= 0) & np.isfinite(s) & np.isfinite(t) & np.isfinite(lane)
    present = np.unique(codes[complete])
    for code in present:
        rid = str(values[code])
        road = net.roads.get(rid)
        if road is None:
            continue
        sel = np.flatnonzero(complete & (codes == code))
        e["known"][sel] = True
        e["length"][sel] = road.length
        e["rht"][sel] = str(road.rule).upper() != "LHT"
        xw, yw, _, hdg = net.road_to_world(rid, s[sel], t[sel])
        e["xw"][sel], e["yw"][sel], e["hdg"][sel] = xw, yw, hdg
        inner, outer = net.lane_borders(rid, s[sel], lane[sel].astype(np.int64))
        e["inner"][sel], e["outer"][sel] = inner, outer
        e["ltype"][sel] = net.lane_type(rid, s[sel], lane[sel])
    return e


def _pos_tol(ctx: Context, sv: StatesView) -> np.ndarray:
    sx, sy = sv.col("x_std"), sv.col("y_std")
    sig = np.sqrt(np.nan_to_num(sx) ** 2 + np.nan_to_num(sy) ** 2) if sx is not None and \
        sy is not None else np.zeros(sv.n)
    return np.maximum(ctx.config.map.tolerance_m, ctx.config.map.z * sig)


@rule("map.incomplete_road_coordinates", "error", "Road coordinates partly null",
      "states.parquet: row {row}: participant {participant_id}: {present} set but {missing} null",
      enforces="docs/format.md §5: road_id, lane_id, road_s, road_t are null together, where off-map", scope="rows")
def incomplete_road_coordinates(ctx: Context) -> Iterator[Hits]:
    """A state has some of road_id, lane_id, road_s, road_t but not all: either it is on the map
    (all set) or off it (all null)."""
    sv = ctx.states_view
    if sv is None:
        return
    rs = sv.strings("road_id")
    cols = {"road_id": (rs[0] >= 0) if rs is not None else None}
    for c in ("lane_id", "road_s", "road_t"):
        v = sv.col(c)
        cols[c] = np.isfinite(v) if v is not None else None
    if any(v is None for v in cols.values()):
        return
    m = np.column_stack(list(cols.values()))
    k = m.sum(1)
    bad = (k > 0) & (k < 4)
    if bad.any():
        i = np.flatnonzero(bad)
        names = np.array(list(cols), dtype=object)
        present = [", ".join(names[m[r]]) for r in i[:1000]]
        missing = [", ".join(names[~m[r]]) for r in i[:1000]]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "present": present, "missing": missing},
                   const={**_F, "column": "road_id"})


@rule("map.unknown_road", "error", "road_id not in the map",
      "states.parquet: row {row}: road_id {road_id!r} is not a road of the map ({n_rows} rows)",
      enforces="docs/format.md §5: road_id is an OpenDRIVE road of map.xodr", scope="rows")
def unknown_road(ctx: Context) -> Iterator[Hits]:
    """A state names a road that map.xodr does not contain. One finding per unknown road id, at
    its first row."""
    sv, net = ctx.states_view, ctx.network
    if sv is None or net is None:
        return
    rs = sv.strings("road_id")
    if rs is None:
        return
    codes, values = rs
    unknown = np.array([str(v) not in net.roads for v in values], dtype=bool)
    if not unknown.any():
        return
    bad = (codes >= 0) & unknown[np.maximum(codes, 0)]
    if bad.any():
        u, first, counts = np.unique(codes[bad], return_index=True, return_counts=True)
        i = np.flatnonzero(bad)[first]
        o = np.argsort(sv.row[i])
        i, u, counts = i[o], u[o], counts[o]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "road_id": values[u].astype(str),
                                         "n_rows": counts},
                   const={**_F, "column": "road_id"})


@rule("map.unknown_lane", "error", "Lane or road_s not on the road",
      "states.parquet: row {row}: road {road_id} has {what}",
      enforces="docs/format.md §5: lane_id is an OpenDRIVE lane of the road at road_s; road_s lies on "
               "the road", scope="rows")
def unknown_lane(ctx: Context) -> Iterator[Hits]:
    """road_s lies outside [0, road length] (beyond ``[map] s_margin_m``), or the road has no
    lane ``lane_id`` in the lane section at road_s."""
    e = road_eval(ctx)
    sv = ctx.states_view
    if e is None:
        return
    mg = ctx.config.map.s_margin_m
    s, lane = e["s"], e["lane"]
    off_s = e["known"] & ((s < -mg) | (s > e["length"] + mg))
    no_lane = e["known"] & ~off_s & (lane != 0) & np.isnan(e["inner"])
    bad = off_s | no_lane
    if bad.any():
        i = np.flatnonzero(bad)
        what = [f"no road_s = {s[r]:.3f} (length {e['length'][r]:.3f})" if off_s[r] else
                f"no lane {int(lane[r])} at road_s = {s[r]:.3f}" for r in i[:1000]]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "road_id": e["values"][e["codes"][i]],
                                         "lane_id": lane[i].astype(np.int64), "what": what},
                   const={**_F, "column": "road_s,lane_id"})


@rule("map.road_position_mismatch", "error", "Road coordinates disagree with x/y",
      "states.parquet: row {row}: (road {road_id}, s {s}, t {t}) lies {value} m from x/y "
      "(tolerance {tolerance} m)",
      enforces="docs/format.md §5: road_s, road_t are consistent with x, y through the map", scope="rows")
def road_position_mismatch(ctx: Context) -> Iterator[Hits]:
    """The point that (road_id, road_s, road_t) gives through the map lies farther from the state's
    x/y than max(``[map] tolerance_m`` (0.1 m), z sigma of the position)."""
    e = road_eval(ctx)
    sv = ctx.states_view
    if e is None:
        return
    x, y = sv.col("x"), sv.col("y")
    if x is None or y is None:
        return
    d = np.hypot(e["xw"] - x, e["yw"] - y)
    tol = _pos_tol(ctx, sv)
    bad = e["known"] & np.isfinite(x) & np.isfinite(y) & ~(d <= tol)  # null x/y: structure rules
    bad &= ~((e["s"] < -ctx.config.map.s_margin_m) | (e["s"] > e["length"] + ctx.config.map.s_margin_m))
    if bad.any():
        i = np.flatnonzero(bad)
        yield Hits(total=len(i), arrays={
            "row": sv.row[i], "participant_id": sv.pid[i], "time": sv.t[i], "x": x[i], "y": y[i],
            "road_id": e["values"][e["codes"][i]], "lane_id": e["lane"][i].astype(np.int64),
            "s": np.round(e["s"][i], 3), "t": np.round(e["t"][i], 3), "value": np.round(d[i], 3),
            "tolerance": np.round(tol[i], 3)}, const={**_F, "column": "road_s,road_t"})


@rule("map.lane_mismatch", "error", "lane_id disagrees with road_t",
      "states.parquet: row {row}: road_t {t} m is not in lane {lane_id} of road {road_id} "
      "(borders {inner} .. {outer} m at s {s})",
      enforces="docs/format.md §5: lane_id is the lane containing (road_s, road_t)", scope="rows")
def lane_mismatch(ctx: Context) -> Iterator[Hits]:
    """road_t lies outside the borders of lane ``lane_id`` at road_s (beyond the position
    tolerance of map.road_position_mismatch)."""
    e = road_eval(ctx)
    sv = ctx.states_view
    if e is None:
        return
    lo = np.fmin(e["inner"], e["outer"])
    hi = np.fmax(e["inner"], e["outer"])
    tol = _pos_tol(ctx, sv)
    t = e["t"]
    bad = e["known"] & np.isfinite(lo) & ((t < lo - tol) | (t > hi + tol))
    if bad.any():
        i = np.flatnonzero(bad)
        yield Hits(total=len(i), arrays={
            "row": sv.row[i], "participant_id": sv.pid[i], "time": sv.t[i],
            "road_id": e["values"][e["codes"][i]], "lane_id": e["lane"][i].astype(np.int64),
            "s": np.round(e["s"][i], 3), "t": np.round(t[i], 3), "inner": np.round(e["inner"][i], 3),
            "outer": np.round(e["outer"][i], 3)}, const={**_F, "column": "lane_id"})


@rule("map.lane_offset_mismatch", "error", "lane_offset disagrees with road_t",
      "states.parquet: row {row}: lane_offset {value} m, but road_t {t} m lies {expected} m from "
      "the centre of lane {lane_id}",
      enforces="docs/format.md §2: lane_offset is the offset from the lane's centre line, positive to "
               "the left", scope="rows")
def lane_offset_mismatch(ctx: Context) -> Iterator[Hits]:
    """``lane_offset`` differs from road_t minus the centre of lane ``lane_id`` at road_s by more
    than the position tolerance (states whose road_t is not in their lane are left to
    map.lane_mismatch)."""
    e = road_eval(ctx)
    sv = ctx.states_view
    if e is None:
        return
    lo = sv.col("lane_offset")
    if lo is None:
        return
    expected = e["t"] - 0.5 * (e["inner"] + e["outer"])
    tol = _pos_tol(ctx, sv)
    in_lane = (e["t"] >= np.fmin(e["inner"], e["outer"]) - tol) & \
        (e["t"] <= np.fmax(e["inner"], e["outer"]) + tol)  # else map.lane_mismatch reports it
    bad = e["known"] & in_lane & np.isfinite(lo) & (np.abs(lo - expected) > tol)
    if bad.any():
        i = np.flatnonzero(bad)
        yield Hits(total=len(i), arrays={
            "row": sv.row[i], "participant_id": sv.pid[i], "time": sv.t[i],
            "road_id": e["values"][e["codes"][i]], "lane_id": e["lane"][i].astype(np.int64),
            "value": np.round(lo[i], 3), "t": np.round(e["t"][i], 3),
            "expected": np.round(expected[i], 3)}, const={**_F, "column": "lane_offset"})


def _first_per_participant(sv: StatesView, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = np.flatnonzero(mask)
    first = np.r_[0, np.flatnonzero(np.diff(sv.seg[idx])) + 1]
    return idx[first], np.diff(np.r_[first, len(idx)])


@rule("map.off_drivable_lane", "warning", "Vehicle off any drivable lane",
      "states.parquet: row {row}: {class_} {participant_id} is {where} ({n_samples} samples)", scope="rows",
      enforces=quality("on_lanes"))
def off_drivable_lane(ctx: Context) -> Iterator[Hits]:
    """A vehicle (car, van, truck, bus, motorcycle, trailer) is off the map (null road
    coordinates) or in a lane whose OpenDRIVE type is not drivable (shoulder, border, sidewalk...).
    One finding per participant."""
    sv = ctx.states_view
    e = road_eval(ctx)
    if sv is None or e is None:
        return
    veh = sv.vehicle & (sv.cls != "railvehicle")
    from aveas_format.opendrive.lanes import DRIVABLE_TYPES

    off_map = veh & ~e["has_road"]
    typed = e["known"] & (e["ltype"] != None)  # noqa: E711
    not_drivable = veh & typed & ~np.isin(e["ltype"], list(DRIVABLE_TYPES))
    bad = off_map | not_drivable
    if bad.any():
        i, counts = _first_per_participant(sv, bad)
        where = np.where(off_map[i], "off the map", "")
        where = [w or f"in a {e['ltype'][r]} lane (lane {int(e['lane'][r])} of road "
                 f"{e['values'][e['codes'][r]]})" for w, r in zip(where[:1000], i[:1000])]
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "class_": sv.cls[i], "where": where,
                                         "n_samples": counts}, const={**_F, "column": "lane_id"})


@rule("map.wrong_way", "warning", "Driving against the lane direction",
      "states.parquet: row {row}: {class_} {participant_id} drives against the direction of lane "
      "{lane_id} of road {road_id} for {duration} s", scope="rows",
      enforces=quality("on_lanes"))
def wrong_way(ctx: Context) -> Iterator[Hits]:
    """A vehicle faster than walking speed moves more than ``[map] wrong_way_angle`` away from
    the driving direction of its lane (right lanes along +s in right-hand traffic, left lanes
    against it; the reverse under LHT) for at least ``min_wrong_way_s``. Bidirectional lanes are
    exempt. Often a sign of swapped lane signs or a mirrored map."""
    sv = ctx.states_view
    e = road_eval(ctx)
    if sv is None or e is None or ctx.meta is None:
        return
    vx, vy = sv.col("vx"), sv.col("vy")
    if vx is None or vy is None:
        return
    sp = np.hypot(vx, vy)
    lane = e["lane"]
    ok = sv.vehicle & e["known"] & (lane != 0) & (sp > ctx.config.kinematics.walking_speed)
    ok &= e["ltype"] != "bidirectional"
    expected = np.where((lane < 0) == e["rht"], 1.0, -1.0)
    along = np.cos(np.arctan2(vy, vx) - e["hdg"]) * expected
    bad = ok & (along < np.cos(ctx.config.map.wrong_way_angle))
    if not bad.any():
        return
    i, counts = _first_per_participant(sv, bad)
    dur = counts / ctx.meta.nominal_rate_hz
    keep = dur >= ctx.config.map.min_wrong_way_s
    i, dur = i[keep], dur[keep]
    if len(i):
        yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                         "time": sv.t[i], "class_": sv.cls[i],
                                         "road_id": e["values"][e["codes"][i]],
                                         "lane_id": lane[i].astype(np.int64),
                                         "duration": np.round(dur, 2)},
                   const={**_F, "column": "vx,vy"})


# --- a recording that is not on its map (the test is aveas_format.mapref.offmap's) ---------------

def _merge_off_road(parts: list[tuple[int, int, np.ndarray]]) -> tuple[int, int, np.ndarray] | None:
    from aveas_format.mapref.offmap import sample

    parts = [p for p in parts if p is not None]
    if not parts:
        return None
    xy = np.vstack([p[2] for p in parts])
    return sum(p[0] for p in parts), sum(p[1] for p in parts), xy[sample(np.arange(len(xy)))]


@collector("map.off_road", merge=_merge_off_road)
def _off_road(ctx: Context) -> tuple[int, int, np.ndarray] | None:
    """(states, states on no road, a sample of their x/y) of one batch: of the vehicles, or of
    everyone in a batch without vehicles."""
    from aveas_format.mapref.offmap import off_road_counts

    sv = ctx.states_view
    rs = sv.strings("road_id") if sv is not None else None
    x, y = (sv.col("x"), sv.col("y")) if sv is not None else (None, None)
    if rs is None or x is None or y is None:
        return None
    return off_road_counts(rs[0] >= 0, x, y, sv.vehicle if sv.vehicle.any() else None)


@rule("map.mostly_off_road", "error", "The recording is mostly off the map",
      "states.parquet: {off} of {n} {who} states ({share} %) are on no road of the map: {causes}",
      enforces="docs/format.md §1-2: positions are in the frame of map.xodr, the map of the recorded "
               "site", needs=("map.off_road",))
def mostly_off_road(ctx: Context) -> Iterator[Hit]:
    """More than ``[map] off_road_share`` (default half) of the vehicles' states are on no road of
    the map (null road coordinates) — in a recording without vehicles, of all states farther than
    ``[map] off_road_walk_m`` from every lane: the positions are not in the map's frame. The message names the
    likely causes (a map of another site, the wrong CRS, the map header's ``<offset>``, x/y
    swapped, another unit, a left-handed frame) and says which of the cheap ones (swapped axes,
    mm/cm/feet/km, the offset, y mirrored) would put the sampled positions on the map. Every
    import runs the same test (:mod:`aveas_format.mapref.offmap`) and warns."""
    from aveas_format.mapref.offmap import mostly_off

    got = ctx.collected.get("map.off_road")
    net = ctx.network
    if got is None or net is None:
        return
    n, off, xy = got
    cfg = ctx.config.map
    sv = ctx.states_view
    found = mostly_off(net, n, off, xy, sv is not None and bool(sv.vehicle.any()),
                       share=cfg.off_road_share, min_states=cfg.off_road_min_states,
                       walk_m=cfg.off_road_walk_m)
    if found is None:
        return
    causes = found.message().split(": ", 1)[1]
    yield Hit(file="states.parquet", table="states", column="x,y", n=found.n, off=found.off,
              who=found.who, share=round(100.0 * found.share, 1), causes=causes)
