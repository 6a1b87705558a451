"""OpenSCENARIO positions and trajectory shapes -> world coordinates (through the OpenDRIVE engine).

Positions (:func:`position`): ``WorldPosition``, ``LanePosition``, ``RoadPosition``,
``RelativeWorldPosition``, ``RelativeObjectPosition``, ``RelativeLanePosition`` (``ds`` or
``dsLane``), ``RelativeRoadPosition`` and ``GeoPosition`` (through the recording's CRS). Not
supported (an error naming the kind): ``RoutePosition``, ``TrajectoryPosition``.
Relative positions are taken relative to the referenced entity's state when the action starts.
Headings: an ``Orientation`` (absolute, or relative to the road / the referenced entity); without
one, a lane or road position takes the lane's driving direction, a world position its ``h`` (or,
on a trajectory, the path's tangent).

Shapes (:func:`shape_path`): ``Polyline`` (vertices, straight segments), ``Clothoid`` (curvature,
``curvatureDot``/``curvaturePrime``, length, optional ``startTime``/``stopTime``),
``ClothoidSpline`` (1.3: segments of linear curvature, each from the previous end or its own
``PositionStart``, ``hOffset``, ``timeStart``/``timeEnd``) and
``Nurbs`` (rational B-spline of any order, control point weights and times, knot vector; evaluated
with :class:`scipy.interpolate.BSpline` on homogeneous coordinates). The result is a dense path:
arc length, x, y, z, tangent heading, the heading given by the file where there is one, and the
time the file gives (vertex / control point times; NaN where it gives none).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from aveas_format.errors import FormatError

_STEP = 0.5  # m: sampling step of curved shapes
POSITION_KINDS = {"WorldPosition", "LanePosition", "RoadPosition", "RelativeWorldPosition",
                  "RelativeObjectPosition", "RelativeLanePosition", "RelativeRoadPosition",
                  "GeoPosition", "RoutePosition", "TrajectoryPosition"}


@dataclass
class Pose:
    x: float
    y: float
    z: float = 0.0
    h: float | None = None


class ShapeError(FormatError):
    """A position or shape that cannot be evaluated; names the XML line."""


def attr(el, name: str, default: float | None = 0.0) -> float | None:
    v = el.get(name)
    if v is None:
        return default
    try:
        return float(v)
    except ValueError:
        raise ShapeError(f"<{el.tag}> {name}={v!r} is not a number", line=el.sourceline) from None


def _orient(el, base: float | None, road_h: float | None = None) -> float | None:
    """Heading from an ``Orientation`` child: absolute, or relative to ``road_h`` / ``base``."""
    o = el.find("Orientation")
    if o is None or o.get("h") is None:
        return base
    h = attr(o, "h")
    if o.get("type", "relative") == "absolute":
        return h
    ref = road_h if road_h is not None else base
    return h + (ref or 0.0)


class Resolver:
    """Evaluates positions on a map, relative to entity poses given by ``pose_of(name)``."""

    def __init__(self, net, pose_of, frame=None) -> None:
        self.net = net
        self.pose_of = pose_of
        self.frame = frame  # LocalFrame of the recording's CRS (GeoPosition), or None

    def _road(self, road_id: str, s: float, t: float, lane: int | None, el):
        try:
            x, y, z, hdg = self.net.road_to_world(road_id, np.array([s]), np.array([t]))
        except KeyError:
            raise ShapeError(f"<{el.tag}> roadId={road_id!r}: no such road in the map",
                             line=el.sourceline) from None
        h = float(hdg[0])
        rht = self.net.roads[str(road_id)].rule.upper() != "LHT"
        if lane is not None and (lane > 0) == rht:
            h += math.pi  # driving direction of the lane
        return float(x[0]), float(y[0]), float(z[0]), h, float(hdg[0])

    def lane_t(self, road_id: str, s: float, lane: int, el) -> float:
        try:
            inner, outer = self.net.lane_borders(road_id, np.array([s]), np.array([lane]))
        except KeyError:
            raise ShapeError(f"<{el.tag}> roadId={road_id!r}: no such road in the map",
                             line=el.sourceline) from None
        if not np.isfinite(inner[0]):
            raise ShapeError(f"<{el.tag}> lane {lane} does not exist on road {road_id} at s={s:g}",
                             line=el.sourceline)
        return 0.5 * float(inner[0] + outer[0])

    def road_of(self, pose: Pose, el):
        """(road id, s, t, lane id) of a pose (its nearest road)."""
        pr = self.net.world_to_road(np.array([pose.x]), np.array([pose.y]),
                                    None if pose.h is None else np.array([pose.h]))
        if pr.road_id[0] is None:
            raise ShapeError(f"<{el.tag}>: the entity {el.get('entityRef')!r} is on no road, so a "
                             "road-relative position cannot be evaluated", line=el.sourceline)
        return str(pr.road_id[0]), float(pr.s[0]), float(pr.t[0]), int(pr.lane_id[0])

    def position(self, pos) -> Pose:
        """The pose of a ``<Position>`` element, of an element holding a position kind (such as
        ``TargetPositionMaster``), or of a position kind element itself."""
        el = pos if pos.tag in POSITION_KINDS else next((c for c in pos if isinstance(c.tag, str)), None)
        if el is None:
            raise ShapeError("empty <Position>", line=pos.sourceline)
        tag = el.tag
        if tag == "WorldPosition":
            return Pose(attr(el, "x"), attr(el, "y"), attr(el, "z"), attr(el, "h", None))
        if tag in ("LanePosition", "RoadPosition"):
            road, s = el.get("roadId"), attr(el, "s")
            if tag == "LanePosition":
                lane = int(attr(el, "laneId"))
                t = self.lane_t(road, s, lane, el) + attr(el, "offset")
            else:
                lane, t = None, attr(el, "t")
            x, y, z, h, rh = self._road(road, s, t, lane, el)
            return Pose(x, y, z, _orient(el, h, rh))
        if tag in ("RelativeWorldPosition", "RelativeObjectPosition"):
            ref = self._ref(el)
            dx, dy, dz = attr(el, "dx"), attr(el, "dy"), attr(el, "dz")
            if tag == "RelativeObjectPosition":
                c, s_ = math.cos(ref.h or 0.0), math.sin(ref.h or 0.0)
                dx, dy = dx * c - dy * s_, dx * s_ + dy * c
            return Pose(ref.x + dx, ref.y + dy, ref.z + dz, _orient(el, ref.h))
        if tag in ("RelativeLanePosition", "RelativeRoadPosition"):
            ref = self._ref(el)
            road, s, t, lane = self.road_of(ref, el)
            if tag == "RelativeRoadPosition":
                s, t = s + attr(el, "ds"), t + attr(el, "dt")
                x, y, z, h, rh = self._road(road, s, t, None, el)
                return Pose(x, y, z, _orient(el, ref.h if ref.h is not None else h, rh))
            dl = int(attr(el, "dLane"))
            new = lane + dl
            if lane != 0 and (new == 0 or (new > 0) != (lane > 0)):  # lane 0 is not a lane
                new += 1 if dl > 0 else -1
            s += attr(el, "ds") if el.get("ds") is not None else attr(el, "dsLane") * (
                -1.0 if lane > 0 else 1.0)
            t = self.lane_t(road, s, new, el) + attr(el, "offset")
            x, y, z, h, rh = self._road(road, s, t, new, el)
            return Pose(x, y, z, _orient(el, h, rh))
        if tag == "GeoPosition":
            if self.frame is None:
                raise ShapeError("GeoPosition needs the recording's CRS: the map has no "
                                 "<geoReference>; pass --crs", line=el.sourceline)
            lat = attr(el, "latitudeDeg", None)
            lon = attr(el, "longitudeDeg", None)
            if lat is None:  # OpenSCENARIO 1.0: radians
                lat, lon = math.degrees(attr(el, "latitude")), math.degrees(attr(el, "longitude"))
            x, y = self.frame.from_wgs84(np.array([lon]), np.array([lat]))
            return Pose(float(x[0]), float(y[0]), attr(el, "altitude"), _orient(el, None))
        raise ShapeError(f"position kind <{tag}> is not supported (World, Lane, Road, Geo and "
                         "the Relative* positions are)", line=el.sourceline)

    def _ref(self, el) -> Pose:
        name = el.get("entityRef")
        pose = self.pose_of(name)
        if pose is None:
            raise ShapeError(f"<{el.tag}> entityRef={name!r}: that entity has no position yet",
                             line=el.sourceline)
        return pose


@dataclass
class Path_:
    """A dense path: arc length ``s``, positions, the tangent heading, the file's heading (NaN
    where none) and the file's time (NaN where none)."""

    s: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    tangent: np.ndarray
    h: np.ndarray
    time: np.ndarray


def _path(x, y, z, h, time) -> Path_:
    x, y, z = (np.asarray(a, np.float64) for a in (x, y, z))
    d = np.hypot(np.diff(x), np.diff(y))
    s = np.r_[0.0, np.cumsum(d)]
    seg = np.arctan2(np.diff(y), np.diff(x))
    if len(seg) == 0:
        tang = np.array([np.nan_to_num(np.asarray(h, float)[0]) if len(h) else 0.0])
    else:
        tang = np.r_[seg, seg[-1]]
    return Path_(s, x, y, z, tang, np.asarray(h, np.float64), np.asarray(time, np.float64))


def _clothoid(x0, y0, h0, k0, dk, length, n=None):
    """Points along a clothoid (curvature k0 + dk s), by integrating the heading numerically."""
    n = n or max(int(math.ceil(abs(length) / _STEP)), 2)
    s = np.linspace(0.0, length, n + 1)
    h = h0 + k0 * s + 0.5 * dk * s * s
    # trapezoid of (cos h, sin h) on a fine grid: error O(step^2 k^2), < 1 mm for 0.5 m steps
    ds = np.diff(s)
    x = x0 + np.r_[0.0, np.cumsum(0.5 * (np.cos(h[1:]) + np.cos(h[:-1])) * ds)]
    y = y0 + np.r_[0.0, np.cumsum(0.5 * (np.sin(h[1:]) + np.sin(h[:-1])) * ds)]
    return s, x, y, h


def shape_path(shape, res: Resolver, start: Pose) -> Path_:
    """The dense path of a ``<Shape>`` (see the module doc); ``start`` is the entity's pose when
    the action starts (the default start of a clothoid)."""
    kind = next((c for c in shape if isinstance(c.tag, str)), None)
    if kind is None:
        raise ShapeError("empty <Shape>", line=shape.sourceline)
    if kind.tag == "Polyline":
        vs = kind.findall("Vertex")
        if not vs:
            raise ShapeError("<Polyline> without vertices", line=kind.sourceline)
        poses = [res.position(_pos_of(v)) for v in vs]
        if shape.getparent() is not None and shape.getparent().get("closed") == "true" and len(vs) > 1:
            poses.append(poses[0])  # a closed trajectory returns to its first vertex
            vs = [*vs, vs[0]]
        return _path([p.x for p in poses], [p.y for p in poses], [p.z for p in poses],
                     [np.nan if p.h is None else p.h for p in poses],
                     [attr(v, "time", np.nan) for v in vs])
    if kind.tag == "Clothoid":
        p0 = res.position(_pos_of(kind)) if _pos_of(kind, False) is not None else start
        k0 = attr(kind, "curvature")
        dk = attr(kind, "curvaturePrime", None)
        dk = attr(kind, "curvatureDot") if dk is None else dk
        length = attr(kind, "length")
        s, x, y, h = _clothoid(p0.x, p0.y, p0.h or 0.0, k0, dk, length)
        t0, t1 = attr(kind, "startTime", np.nan), attr(kind, "stopTime", np.nan)
        time = np.full(len(s), np.nan)
        if np.isfinite(t0) and np.isfinite(t1):
            time = t0 + (t1 - t0) * s / max(length, 1e-9)
        return _path(x, y, np.full(len(s), p0.z), h, time)
    if kind.tag == "ClothoidSpline":
        segs = kind.findall("ClothoidSplineSegment")
        ps = segs[0].find("PositionStart") if segs else None
        p = res.position(ps) if ps is not None else start
        xs, ys, hs, ts = [np.array([p.x])], [np.array([p.y])], [np.array([p.h or 0.0])], []
        x0, y0, h0 = p.x, p.y, p.h or 0.0
        times = []
        for k, seg in enumerate(kind.iterfind("ClothoidSplineSegment")):
            ps = seg.find("PositionStart")
            if k and ps is not None:  # a segment may start elsewhere (a discontinuous spline)
                q = res.position(ps)
                x0, y0, h0 = q.x, q.y, q.h if q.h is not None else h0
                xs.append(np.array([x0])), ys.append(np.array([y0])), hs.append(np.array([h0]))
                ts[-1] += 1
            h0 += attr(seg, "hOffset")
            length = attr(seg, "length")
            k0, k1 = attr(seg, "curvatureStart"), attr(seg, "curvatureEnd")
            s, x, y, h = _clothoid(x0, y0, h0, k0, (k1 - k0) / max(length, 1e-9), length)
            xs.append(x[1:]), ys.append(y[1:]), hs.append(h[1:])
            ts.append(len(s) - 1)
            times.append(attr(seg, "timeStart", np.nan))
            x0, y0, h0 = x[-1], y[-1], h[-1]
        x, y, h = np.concatenate(xs), np.concatenate(ys), np.concatenate(hs)
        time = np.full(len(x), np.nan)
        t_end = attr(kind, "timeEnd", np.nan)
        if times and all(np.isfinite(times)) and np.isfinite(t_end):
            idx = np.r_[0, np.cumsum(ts)]
            knots = np.r_[times, t_end]
            path = _path(x, y, np.full(len(x), p.z), h, time)
            path.time = np.interp(path.s, path.s[idx], knots)
            return path
        return _path(x, y, np.full(len(x), p.z), h, time)
    if kind.tag == "Nurbs":
        return _nurbs(kind, res)
    raise ShapeError(f"trajectory shape <{kind.tag}> is not supported (Polyline, Clothoid, "
                     "ClothoidSpline, Nurbs are)", line=kind.sourceline)


def _pos_of(el, required: bool = True):
    p = el.find("Position")
    if p is None:  # esmini accepts a position kind element directly
        p = next((c for c in el if isinstance(c.tag, str) and c.tag.endswith("Position")), None)
    if p is None and required:
        raise ShapeError(f"<{el.tag}> has no <Position>", line=el.sourceline)
    return p


def _nurbs(el, res: Resolver) -> Path_:
    from scipy.interpolate import BSpline

    order = int(attr(el, "order", 2))
    cps = el.findall("ControlPoint")
    knots = np.array([attr(k, "value") for k in el.iterfind("Knot")], np.float64)
    if order < 1 or len(cps) < order or len(knots) != len(cps) + order:
        raise ShapeError(f"<Nurbs> order {order} with {len(cps)} control points needs "
                         f"{len(cps) + order} knots, has {len(knots)}", line=el.sourceline)
    if np.any(np.diff(knots) < 0):
        raise ShapeError("<Nurbs> knots must not decrease", line=el.sourceline)
    poses = [res.position(_pos_of(c)) for c in cps]
    w = np.array([attr(c, "weight", 1.0) for c in cps])
    if np.any(w <= 0):
        raise ShapeError("<Nurbs> control point weights must be positive", line=el.sourceline)
    times = np.array([attr(c, "time", np.nan) for c in cps])
    P = np.array([[p.x, p.y, p.z] for p in poses])
    hom = np.c_[P * w[:, None], np.nan_to_num(times) * w, w]
    spl = BSpline(knots, hom, order - 1)
    lo, hi = knots[order - 1], knots[len(cps)]
    # dense enough: ~0.5 m steps along the control polygon
    poly_len = float(np.sum(np.hypot(np.diff(P[:, 0]), np.diff(P[:, 1])))) if len(P) > 1 else 0.0
    u = np.linspace(lo, hi, max(int(poly_len / _STEP), 50) + 1)
    v = spl(u)
    x, y, z = v[:, 0] / v[:, 4], v[:, 1] / v[:, 4], v[:, 2] / v[:, 4]
    time = v[:, 3] / v[:, 4] if np.all(np.isfinite(times)) else np.full(len(u), np.nan)
    return _path(x, y, z, np.full(len(u), np.nan), time)
