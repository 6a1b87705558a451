"""Self-consistency checks of an OpenDRIVE map (``RoadNetwork.check()``).

Each rule has a code, a severity and a message rendered from typed fields (road id, XML line,
value). Codes:

====================== ========= ====================================================================
code                   severity  meaning
====================== ========= ====================================================================
geometry.gap           warning   consecutive geometries: the end of one is > 1 mm from the next start
geometry.heading_jump  warning   consecutive geometries: heading differs by > 1 mrad
geometry.s_mismatch    warning   a geometry's s differs from the previous s + length by > 1 mm
road.length_mismatch   warning   the plan view's length differs from the road's length by > 1 mm
geometry.zero_length   info      a ``<geometry>`` shorter than 1 mm (length 0 or rounding residue);
                                 it is read, it just contributes (almost) nothing
lane.section_length    warning   a lane section shorter than 1 mm: two ``<laneSection>`` at the same
                                 s, one at or after the road's end, or a rounding residue; its lanes
                                 apply nowhere (or over less than 1 mm): the next section's lanes do
lane.negative_width    error     a lane's width is negative somewhere in its section, by more than
                                 ``WIDTH_TOL`` (1 cm)
lane.width_noise       warning   ... by less than ``WIDTH_TOL``: numerical noise of the tool that wrote
                                 the map (e.g. -2.6 mm at a section start in a RoadRunner export)
lane.border_sign       warning   a ``<border>`` record puts a lane's outer border on the other side of
                                 the reference line (a right lane with positive t, a left lane with
                                 negative t); read as the standard says (signed t)
lane.fold              warning   a lane lies farther out than the curve radius (world -> road folds)
link.missing_road      error     a road, junction connection or lane link names a road not in the map
link.missing_junction  error     a road link names a junction not in the map
link.missing_lane      error     a lane link names a lane that the linked section does not have
georef.missing         info      no ``<geoReference>``
georef.no_proj         warning   ``<geoReference>`` without ``+proj`` (needs a lenient interpretation)
georef.utm_no_zone     warning   ``+proj=utm`` without ``+zone``
georef.unparseable     error     pyproj cannot parse the ``<geoReference>``
====================== ========= ====================================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .polygons import section_samples

if TYPE_CHECKING:  # pragma: no cover
    from .core import NetworkCore

GAP_TOL = 1e-3
#: m: lane sections and geometries shorter than this are reported (zero-length or rounding residue)
SHORT_TOL = 1e-3
HEADING_TOL = 1e-3
#: m: a negative lane width smaller than this is numerical noise (a warning), larger an error
WIDTH_TOL = 1e-2


@dataclass(frozen=True, slots=True)
class Finding:
    """One finding: ``code``, ``severity`` (error/warning/info), ``message``, location, value."""

    code: str
    message: str
    severity: str = "error"
    road_id: str | None = None
    line: int | None = None
    value: float | None = None


def _geometry(net: NetworkCore) -> list[Finding]:
    out = []
    pv = net.plan
    xe, ye, he = pv.end_points()
    for i in range(len(pv.road) - 1):
        if pv.road[i] != pv.road[i + 1]:
            continue
        rid = net.road_ids[pv.road[i]]
        gap = float(np.hypot(xe[i] - pv.x0[i + 1], ye[i] - pv.y0[i + 1]))
        if gap > GAP_TOL:
            out.append(
                Finding(
                    "geometry.gap",
                    f"road {rid}: {gap:.4g} m gap before the geometry at s={pv.s0[i + 1]:.6g}",
                    "warning",
                    rid,
                    pv.line[i + 1],
                    gap,
                )
            )
        dh = float(abs((he[i] - pv.h0[i + 1] + np.pi) % (2 * np.pi) - np.pi))
        if dh > HEADING_TOL:
            out.append(
                Finding(
                    "geometry.heading_jump",
                    f"road {rid}: heading jumps by {dh:.4g} rad at s={pv.s0[i + 1]:.6g}",
                    "warning",
                    rid,
                    pv.line[i + 1],
                    dh,
                )
            )
        ds = float(pv.s0[i] + pv.length[i] - pv.s0[i + 1])
        if abs(ds) > GAP_TOL:
            out.append(
                Finding(
                    "geometry.s_mismatch",
                    f"road {rid}: geometry at s={pv.s0[i + 1]:.6g} should start at s={pv.s0[i] + pv.length[i]:.6g}",
                    "warning",
                    rid,
                    pv.line[i + 1],
                    ds,
                )
            )
    short = np.flatnonzero(pv.length < SHORT_TOL)
    for i in short:
        rid = net.road_ids[pv.road[i]]
        kind = net.roads[rid].geometries[i - int(pv.index.road_first[pv.road[i]])].kind
        out.append(Finding(
            "geometry.zero_length",
            f"road {rid}: the <{kind}> geometry at s={pv.s0[i]:.6g} is {pv.length[i]:.3g} m long",
            "info", rid, pv.line[i], float(pv.length[i])))
    for road in net.road_list:
        last = road.geometries[-1]
        d = last.s + last.length - road.length
        if abs(d) > GAP_TOL:
            out.append(
                Finding(
                    "road.length_mismatch",
                    f"road {road.id}: the plan view ends at s={last.s + last.length:.6g}, the road's length is {road.length:.6g}",
                    "warning",
                    road.id,
                    road.line,
                    d,
                )
            )
    return out


def _section_length(road, si: int, length: float) -> Finding | None:
    """A finding for lane section ``si`` of ``road`` when it is shorter than ``SHORT_TOL``."""
    if length >= SHORT_TOL:
        return None
    sec = road.lane_sections[si]
    where = f"road {road.id}: the lane section at s={sec.s:.6g}"
    if sec.s >= road.length:
        why = f"starts at or after the road's end (length {road.length:.6g}): its lanes apply nowhere"
    elif length <= 0:
        why = "starts where the next one does: it has zero length and its lanes apply nowhere"
    else:
        nxt = (f"the next one starts at s={road.lane_sections[si + 1].s:.9g}" if si + 1 < len(road.lane_sections)
               else "as is the whole road" if sec.s <= 0 else f"the road ends at s={road.length:.9g}")
        why = f"is {length:.3g} m long ({nxt})"
    return Finding("lane.section_length", f"{where} {why}", "warning", road.id, sec.line, length)


def _lanes(net: NetworkCore, step: float = 2.0) -> list[Finding]:
    out = []
    lanes = net.lanes
    for gsec in range(len(lanes.section_road)):
        ri = int(lanes.section_road[gsec])
        road = net.road_list[ri]
        sec = road.lane_sections[int(lanes.section_local[gsec])]
        short = _section_length(road, int(lanes.section_local[gsec]),
                                float(lanes.section_end[gsec] - lanes.section_start[gsec]))
        if short is not None:
            out.append(short)
        s = section_samples(net, gsec, step)
        # evaluate just inside each piece's end as well
        s = np.unique(np.concatenate([s, np.maximum(s - 1e-9, s[0])]))
        piece = lanes.pieces_in_section(gsec, s)
        b = lanes.borders(piece, s)
        p0 = piece[0]
        for outers, ids, sign in ((b.left, lanes.lid[p0], 1.0), (b.right, lanes.rid[p0], -1.0)):
            inners = np.concatenate([b.center[:, None], outers[:, :-1]], axis=1)
            width = sign * (outers - inners)
            for k in range(outers.shape[1]):
                if ids[k] == 0:
                    continue
                w = float(width[:, k].min())
                lane = sec.lane(int(ids[k]))
                line = lane.line if lane else sec.line
                if lane is not None and not len(lane.widths) and len(lane.borders):
                    across = sign * outers[:, k] < -1e-9  # outer border beyond the reference line
                    if across.any():
                        out.append(Finding(
                            "lane.border_sign",
                            f"road {road.id}: lane {ids[k]} of the section at s={sec.s:.6g}: its <border> "
                            f"is at t={float(outers[np.argmax(across), k]):.4g} m, on the other side of the "
                            "reference line; read as signed t (ASAM OpenDRIVE 1.8 11.6.2), not as a distance",
                            "warning", road.id, line, float(outers[np.argmax(across), k])))
                if w < -WIDTH_TOL:
                    out.append(Finding(
                        "lane.negative_width",
                        f"road {road.id}: lane {ids[k]} of the section at s={sec.s:.6g} has width {w:.4g} m",
                        "error", road.id, line, w))
                elif w < -1e-9:
                    out.append(Finding(
                        "lane.width_noise",
                        f"road {road.id}: lane {ids[k]} of the section at s={sec.s:.6g} has width {w:.4g} m "
                        f"(within the {WIDTH_TOL * 1000:g} mm tolerance for numerical noise)",
                        "warning", road.id, line, w))
        x, y, h, kap, _, _ = net.plan.at(np.full(len(s), ri), s)
        tl, tr = lanes.extent(b)
        fold = ((kap > 0) & (tl * kap >= 1)) | ((kap < 0) & (tr * kap >= 1))
        if fold.any():
            out.append(
                Finding(
                    "lane.fold",
                    f"road {road.id}: lanes reach beyond the curve's centre near s={s[fold][0]:.6g}",
                    "warning",
                    road.id,
                    sec.line,
                    float(s[fold][0]),
                )
            )
    return out


def _section_lane_ids(road, at_start: bool) -> set[int]:
    """Lane ids of the road's first (or last) lane section that has a length (the one a link to
    the road's start or end reaches; zero-length sections apply nowhere)."""
    secs = road.lane_sections
    ends = [sec.s for sec in secs[1:]] + [road.length]
    used = [sec for sec, end in zip(secs, ends) if min(end, road.length) > sec.s] or secs
    sec = used[0] if at_start else used[-1]
    return {ln.id for ln in sec.left + sec.right}


def _links(net: NetworkCore) -> list[Finding]:
    out = []
    roads, junctions = net.roads, net.junctions
    for road in net.road_list:
        for kind, link in (("predecessor", road.predecessor), ("successor", road.successor)):
            if link is None:
                continue
            if link.element_type == "road" and link.element_id not in roads:
                out.append(
                    Finding(
                        "link.missing_road",
                        f"road {road.id}: {kind} road {link.element_id!r} is not in the map",
                        "error",
                        road.id,
                        link.line,
                    )
                )
            elif link.element_type == "junction" and link.element_id not in junctions:
                out.append(
                    Finding(
                        "link.missing_junction",
                        f"road {road.id}: {kind} junction {link.element_id!r} is not in the map",
                        "error",
                        road.id,
                        link.line,
                    )
                )
        if road.junction is not None and road.junction not in junctions:
            out.append(
                Finding(
                    "link.missing_junction",
                    f"road {road.id} belongs to junction {road.junction!r}, which is not in the map",
                    "error",
                    road.id,
                    road.line,
                )
            )
        # lane links within the road and to linked roads
        secs = road.lane_sections
        for i, sec in enumerate(secs):
            for lane in sec.left + sec.right:
                for kind, targets in (("successor", lane.successors), ("predecessor", lane.predecessors)):
                    if not targets:
                        continue
                    nb = i + 1 if kind == "successor" else i - 1
                    if 0 <= nb < len(secs):
                        avail = {ln.id for ln in secs[nb].left + secs[nb].right}
                        where = f"the section at s={secs[nb].s:.6g}"
                    else:
                        link = road.successor if kind == "successor" else road.predecessor
                        if link is None or link.element_type != "road" or link.element_id not in roads:
                            continue
                        other = roads[link.element_id]
                        avail = _section_lane_ids(other, at_start=(link.contact_point or "start") == "start")
                        where = f"road {other.id}"
                    for tid in targets:
                        if tid != 0 and tid not in avail:
                            out.append(
                                Finding(
                                    "link.missing_lane",
                                    f"road {road.id}: lane {lane.id} has {kind} lane {tid}, which {where} lacks",
                                    "error",
                                    road.id,
                                    lane.line,
                                )
                            )
    for j in junctions.values():
        for c in j.connections:
            for role, rid in (("incoming", c.incoming_road), ("connecting", c.target_road)):
                if rid is not None and rid not in roads:
                    out.append(
                        Finding(
                            "link.missing_road",
                            f"junction {j.id}: connection {c.id} names {role} road {rid!r}, which is not in the map",
                            "error",
                            None,
                            c.line,
                        )
                    )
            if c.incoming_road in roads and c.target_road in roads:
                inc, tgt = roads[c.incoming_road], roads[c.target_road]
                inc_ids = {ln.id for sec in inc.lane_sections for ln in sec.left + sec.right}
                tgt_ids = {ln.id for sec in tgt.lane_sections for ln in sec.left + sec.right}
                for ll in c.lane_links:
                    if ll.from_lane not in inc_ids or ll.to_lane not in tgt_ids:
                        out.append(
                            Finding(
                                "link.missing_lane",
                                f"junction {j.id}: connection {c.id} links lane {ll.from_lane} -> {ll.to_lane}, not both present",
                                "error",
                                None,
                                ll.line,
                            )
                        )
    return out


def _georef(net: NetworkCore) -> list[Finding]:
    geo = net.header.geo_reference
    line = net.header.line
    if not geo:
        return [Finding("georef.missing", "the header has no <geoReference>", "info", None, line)]
    tokens = dict(tok.lstrip("+").split("=", 1) if "=" in tok else (tok.lstrip("+"), "") for tok in geo.split())
    if "proj" not in tokens:
        if tokens.get("init") or geo.upper().startswith("EPSG:") or geo.startswith(("PROJCS", "GEOGCS", "PROJCRS")):
            pass
        else:
            return [
                Finding(
                    "georef.no_proj",
                    f"<geoReference> {geo!r} has no +proj; a fallback interpretation is needed",
                    "warning",
                    None,
                    line,
                )
            ]
    out = []
    if tokens.get("proj") == "utm" and "zone" not in tokens:
        out.append(
            Finding("georef.utm_no_zone", f"<geoReference> {geo!r}: +proj=utm without +zone", "warning", None, line)
        )
        return out
    try:
        from pyproj import CRS

        CRS.from_user_input(geo)
    except Exception as exc:  # pyproj raises CRSError (and others for odd input)
        out.append(
            Finding("georef.unparseable", f"<geoReference> {geo!r} cannot be parsed: {exc}", "error", None, line)
        )
    return out


def check_network(net: NetworkCore) -> list[Finding]:
    """All findings for ``net``: geometry continuity, lanes, links, geoReference."""
    return _geometry(net) + _lanes(net) + _links(net) + _georef(net)


__all__ = ["Finding", "check_network"]
