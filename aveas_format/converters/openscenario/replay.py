"""A kinematic replay of an OpenSCENARIO storyboard: the motion a scenario prescribes, as samples.

Not a simulator (no controllers, dynamics or collision avoidance): the storyboard is stepped at a
fixed rate (``rate_hz``) and what the file prescribes is carried out:

- **Init** private actions at t = 0: ``TeleportAction``, ``SpeedAction``, ``FollowTrajectoryAction``.
- **Acts and events** start when their ``StartTrigger`` holds (an element without one starts with
  its parent); condition groups are OR-ed, conditions in a group AND-ed, each condition's
  ``delay`` applied. Evaluated: ``SimulationTimeCondition``, ``StoryboardElementStateCondition``,
  ``ParameterCondition``, and the entity conditions ``ReachPosition``, ``Distance``,
  ``RelativeDistance``, ``TimeHeadway``, ``TimeToCollision``, ``Speed``, ``RelativeSpeed``,
  ``TraveledDistance``, ``StandStill``, ``EndOfRoad`` (lane following reached the end of its road)
  and ``Offroad`` (reference points, Euclidean distances; ``freespace`` subtracts half the
  lengths). A condition of another kind never holds (noted in a warning).
- **Actions** carried out: ``TeleportAction``, ``SpeedAction`` (absolute or relative target;
  step, or a linear / cubic / sinusoidal ramp over time, rate or distance),
  ``FollowTrajectoryAction``, ``LaneChangeAction`` (during lane following: absolute or relative
  target lane, ``targetLaneOffset``, shape over time, distance or rate) and, simplified,
  ``SynchronizeAction`` (the constant speed that brings the entity to its target position when
  the master reaches its own; ``FinalSpeed`` not applied). Other actions (lane offsets,
  longitudinal distance, routing, controllers...) are not replayed; the warning names them.
- **Between trajectories** an entity with a speed follows its lane (road coordinates advanced at
  its speed, lateral offset kept; it stops at the end of a road without a road successor) or, off
  the roads, its heading. An entity at rest is recorded where it rests at the start and end of the
  rest, not on every step (not at all after a timed trajectory, nor before the first one of an
  entity that has not moved yet: its vertices are its motion, as this toolkit's export means it).
- **Trajectories**: vertex / control point times through the ``TimeReference`` (absolute or
  relative to the action's start, ``scale``, ``offset``); untimed shapes (``TimeReference/None``
  or no times) at the entity's speed then (negative: backwards along the path), from
  ``initialDistanceOffset``. A trajectory's own samples (timed polyline vertices, else one per
  step) are recorded: timed vertices as they are; where two timed vertices lie more than
  ``GAP_STEPS`` (3) of the trajectory's median vertex steps apart, the motion between them (the
  straight line a simulator follows) is sampled at that median step too, those samples flagged
  ``interpolated`` (a simulated entity exists and moves between its vertices: a recording
  exported with a gap, a sensor outage, comes back as a simulator would replay it). An untimed
  trajectory of an entity at rest cannot be timed: that entity is not converted (one warning
  line naming it and why).
- Steps are ``1 / rate_hz`` apart, with extra steps where a trajectory or speed ramp ends or a
  condition's delay runs out between two steps (so that chained events start when the element
  they wait for ends).
- The replay ends when the storyboard's ``StopTrigger`` holds; when every act has ended and no
  trajectory runs, it waits for a stop at a simulation time, else at most ``GRACE`` (10 s) (not
  at all without a stop trigger); and it ends after ``max_duration`` s in any case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.converters.openscenario.shapes import Pose, Resolver, ShapeError, attr, shape_path
from aveas_format.errors import FormatError, report_source

#: s the replay goes on after every act has ended and no trajectory runs, waiting for a stop trigger
GRACE = 10.0
ENTITY_CONDITIONS = ("ReachPositionCondition", "DistanceCondition", "RelativeDistanceCondition",
                     "TimeHeadwayCondition", "TimeToCollisionCondition", "SpeedCondition",
                     "RelativeSpeedCondition", "TraveledDistanceCondition", "StandStillCondition",
                     "EndOfRoadCondition", "OffroadCondition")


class EntityError(FormatError):
    """An entity's motion cannot be replayed (the entity is not converted)."""


#: a step between timed vertices longer than this many of the trajectory's median steps is
#: sampled at the median step (the samples flagged ``interpolated``)
GAP_STEPS = 3.0


@dataclass
class Traj:
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    h: np.ndarray
    timed: bool
    #: per sample: filled in between vertices, not prescribed by one (:meth:`fill_gaps`)
    filled: np.ndarray | None = None

    def __post_init__(self) -> None:
        self.h = np.unwrap(np.asarray(self.h, np.float64))  # interpolated without 2 pi jumps
        if self.filled is None:
            self.filled = np.zeros(len(self.t), bool)

    def fill_gaps(self) -> Traj:
        """The trajectory with its gaps (consecutive samples more than :data:`GAP_STEPS` median
        steps apart) sampled at the median step, linearly (``filled`` marks the new samples)."""
        dt = np.diff(self.t)
        if len(dt) < 2:
            return self
        step = float(np.median(dt))
        gaps = np.flatnonzero(dt > GAP_STEPS * step) if step > 0 else np.array([], int)
        if not len(gaps):
            return self
        extra = np.concatenate([self.t[k] + step * np.arange(1, int(np.ceil(dt[k] / step - 1e-9)))
                                for k in gaps])
        t = np.concatenate([self.t, extra])
        order = np.argsort(t, kind="stable")
        at = [np.interp(extra, self.t, v) for v in (self.x, self.y, self.z, self.h)]
        x, y, z, h = (np.concatenate([v, a])[order] for v, a in zip((self.x, self.y, self.z, self.h), at))
        filled = np.r_[np.zeros(len(self.t), bool), np.ones(len(extra), bool)][order]
        return Traj(t[order], x, y, z, h, self.timed, filled)

    def at(self, t: float) -> Pose:
        return Pose(float(np.interp(t, self.t, self.x)), float(np.interp(t, self.t, self.y)),
                    float(np.interp(t, self.t, self.z)), float(np.interp(t, self.t, self.h)))


@dataclass
class Entity:
    name: str
    length: float
    pose: Pose | None = None
    v: float = 0.0
    ramp: tuple[float, float, float, float, str] | None = None  # t0, t1, v0, v1, shape
    traj: Traj | None = None
    # lane motion: road, s, t, direction of s per metre of travel, heading offset from the road's
    lane: tuple[str, float, float, float, float] | None = None
    travelled: float = 0.0
    motion_h: float | None = None  # direction of motion when the last trajectory ended
    road_end_since: float | None = None  # when lane following reached the end of its road
    offroad_since: float | None = None
    lane_id: int = 0  # of lane following
    lat: tuple[float, float, float, float, str] | None = None  # lane change: t0, t1, from, to, shape
    #: the recorded samples: time, x, y, z, heading, filled in (not prescribed by a vertex)
    rows: list[tuple[float, float, float, float, float, bool]] = field(default_factory=list)
    rest_since: float | None = None
    error: str | None = None
    error_line: int | None = None  # the XML line of the action that failed


class Replay:
    def __init__(self, root, net, entities: dict[str, float], *, rate_hz: float,
                 max_duration: float, frame=None, params: dict[str, str] | None = None) -> None:
        self.root = root
        self.net = net
        self.dt = 1.0 / rate_hz
        self.max_duration = max_duration
        self.params = params or {}
        self.ents = {n: Entity(n, length) for n, length in entities.items()}
        self.res = Resolver(net, self._pose_of, frame)
        self.t = 0.0
        # storyboard element (the lxml element: a dict key keeps its proxy, so its identity, alive)
        self.state: dict[Any, tuple[str, float | None, float | None]] = {}  # -> kind, start, end
        self.cond_true: dict[Any, float] = {}
        self.ignored_actions: dict[str, int] = {}
        #: the XML line of the first action / condition of each kind not replayed
        self.ignored_lines: dict[str, int] = {}
        self.clipped: dict[str, int] = {}
        self.wakeups: set[float] = set()  # times between steps at which something happens  # entity -> timed vertices after the end of the replay
        self.ignored_conditions: dict[str, int] = {}
        self.named: dict[str, object] = {}
        for el in root.iter("Story", "Act", "ManeuverGroup", "Maneuver", "Event", "Action"):
            if el.get("name"):
                self.named.setdefault(el.get("name"), el)

    # -- entity state ----------------------------------------------------------------------------
    def _pose_of(self, name: str) -> Pose | None:
        e = self.ents.get(name)
        return None if e is None else e.pose

    def _record(self, e: Entity, t: float, p: Pose) -> None:
        e.rows.append((t, p.x, p.y, p.z, np.nan if p.h is None else p.h, False))

    def _fail(self, e: Entity, why: str, line: int | None = None) -> None:
        if e.error is None:
            e.error, e.error_line = why, line

    # -- actions ---------------------------------------------------------------------------------
    def _private(self, e: Entity, pa) -> float:
        """Carry out one PrivateAction for entity ``e`` now; returns its end time."""
        t = self.t
        child = next((c for c in pa if isinstance(c.tag, str)), None)
        if child is None:
            return t
        try:
            if child.tag == "TeleportAction":
                p = self.res.position(child.find("Position") if child.find("Position") is not None
                                      else child)
                self._end_traj(e, t)
                self._drop_rows_from(e, t)
                if p.h is None:
                    p.h = e.pose.h if e.pose is not None else 0.0
                e.pose, e.lane, e.motion_h, e.road_end_since, e.lat = p, None, None, None, None
                self._rest_mark(e, t, force=True)
                return t
            lca = child.find("LaneChangeAction")
            if child.tag == "LateralAction" and lca is not None:
                return self._lane_change(e, lca)
            if child.tag == "SynchronizeAction":
                return self._synchronize(e, child)
            sa = child.find("SpeedAction")
            if child.tag == "LongitudinalAction" and sa is not None:
                return self._speed(e, sa)
            fta = child.find("FollowTrajectoryAction")
            if child.tag == "RoutingAction" and fta is not None:
                return self._follow(e, fta)
        except (ShapeError, EntityError) as err:
            self._fail(e, err.message, err.where.get("line"))
            return t
        kind = child.tag
        if kind in ("LongitudinalAction", "LateralAction", "RoutingAction", "ControllerAction",
                    "AppearanceAction", "TrailerAction"):
            kind = next((c.tag for c in child if isinstance(c.tag, str)), kind)
        self.ignored_actions[kind] = self.ignored_actions.get(kind, 0) + 1
        self.ignored_lines.setdefault(kind, child.sourceline)
        return t

    def _speed(self, e: Entity, sa) -> float:
        tgt = sa.find("SpeedActionTarget")
        abs_ = tgt.find("AbsoluteTargetSpeed") if tgt is not None else None
        rel = tgt.find("RelativeTargetSpeed") if tgt is not None else None
        if abs_ is not None:
            v1 = attr(abs_, "value")
        elif rel is not None:
            other = self.ents.get(rel.get("entityRef"))
            base = other.v if other is not None else 0.0
            val = attr(rel, "value")
            v1 = base * val if rel.get("speedTargetValueType") == "factor" else base + val
        else:
            raise EntityError("SpeedAction without a target", line=sa.sourceline)
        dyn = sa.find("SpeedActionDynamics")
        shape = dyn.get("dynamicsShape", "step") if dyn is not None else "step"
        dim = dyn.get("dynamicsDimension", "time") if dyn is not None else "time"
        val = attr(dyn, "value") if dyn is not None else 0.0
        v0 = e.v
        dur = 0.0
        if shape != "step" and val > 0:
            if dim == "time":
                dur = val
            elif dim == "rate":
                dur = abs(v1 - v0) / val
            elif dim == "distance":
                dur = 2 * val / max(abs(v0 + v1), 1e-9)
        if dur <= 0:
            e.v, e.ramp = v1, None
            return self.t
        e.ramp = (self.t, self.t + dur, v0, v1, shape)
        return self.t + dur

    def _lane_change(self, e: Entity, lca) -> float:
        """``LaneChangeAction`` during lane following: the lateral position moves from the current
        one to the target lane's centre (+ ``targetLaneOffset``) along the dynamics shape, over
        its time, distance (at the current speed) or rate (m/s sideways)."""
        if e.pose is None or e.traj is not None:
            raise EntityError("LaneChangeAction while on a trajectory or without a position",
                              line=lca.sourceline)
        self._acquire_lane(e)
        road, s, t, direction, _ = e.lane
        if not road:
            raise EntityError("LaneChangeAction off the roads", line=lca.sourceline)
        tgt = lca.find("LaneChangeTarget")
        absl = tgt.find("AbsoluteTargetLane") if tgt is not None else None
        rel = tgt.find("RelativeTargetLane") if tgt is not None else None
        if absl is not None:
            lane = int(attr(absl, "value"))
        elif rel is not None:
            ref = self.ents.get(rel.get("entityRef"))
            if ref is None or ref.pose is None:
                raise EntityError(f"LaneChangeAction: no entity {rel.get('entityRef')!r}",
                                  line=rel.sourceline)
            self._acquire_lane(ref)
            base, step = ref.lane_id, int(attr(rel, "value"))
            # positive: to the left as seen in the reference's driving direction
            lane = base + step * (1 if ref.lane and ref.lane[3] > 0 else -1)
            if base != 0 and (lane == 0 or (lane > 0) != (base > 0)):
                lane += 1 if lane - base > 0 else -1
        else:
            raise EntityError("LaneChangeAction without a target lane", line=lca.sourceline)
        t_to = self.res.lane_t(road, s, lane, lca) + attr(lca, "targetLaneOffset")
        dyn = lca.find("LaneChangeActionDynamics")
        shape = dyn.get("dynamicsShape", "sinusoidal") if dyn is not None else "sinusoidal"
        dim = dyn.get("dynamicsDimension", "time") if dyn is not None else "time"
        val = attr(dyn, "value") if dyn is not None else 0.0
        dur = (val if dim == "time" else val / max(abs(e.v), 1e-9) if dim == "distance"
               else abs(t_to - t) / val if dim == "rate" and val > 0 else 0.0)
        if shape == "step" or dur <= 0:
            e.lane, e.lat = (road, s, t_to, *e.lane[3:]), None
            return self.t
        e.lat = (self.t, self.t + dur, t, t_to, shape)
        e.lane_id = lane
        return self.t + dur

    def _synchronize(self, e: Entity, sa) -> float:
        """``SynchronizeAction``, simplified: the speed that brings the entity (straight-line
        distance) to ``TargetPosition`` when the master, at its speed or along its timed
        trajectory, reaches ``TargetPositionMaster``; ``FinalSpeed`` is not applied."""
        master = self.ents.get(sa.get("masterEntityRef"))
        tpm, tp = sa.find("TargetPositionMaster"), sa.find("TargetPosition")
        if master is None or master.pose is None or tpm is None or tp is None or e.pose is None:
            raise EntityError("SynchronizeAction: master entity or target positions missing",
                              line=sa.sourceline)
        qm, q = self.res.position(tpm), self.res.position(tp)
        if master.traj is not None and master.traj.timed:
            d = np.hypot(master.traj.x - qm.x, master.traj.y - qm.y)
            arrive = float(master.traj.t[int(np.argmin(d))]) - self.t
        elif abs(master.v) > 1e-9:
            arrive = math.hypot(master.pose.x - qm.x, master.pose.y - qm.y) / abs(master.v)
        else:
            raise EntityError(f"SynchronizeAction: the master {master.name!r} does not move",
                              line=sa.sourceline)
        if arrive <= 1e-6:
            raise EntityError("SynchronizeAction: the master is already at its target",
                              line=sa.sourceline)
        e.v, e.ramp = math.hypot(e.pose.x - q.x, e.pose.y - q.y) / arrive, None
        return self.t + arrive

    def _drop_rows_from(self, e: Entity, t: float) -> None:
        """An action at ``t`` replaces the sample default motion recorded at ``t``."""
        while e.rows and e.rows[-1][0] >= t - 1e-9:
            e.rows.pop()

    def _follow(self, e: Entity, fta) -> float:
        traj = fta.find("Trajectory")
        if traj is None:
            traj = fta.find("TrajectoryRef/Trajectory")
        if traj is None:
            ref = fta.find("TrajectoryRef/CatalogReference")
            if ref is None:
                ref = fta.find("CatalogReference")
            if ref is not None and self.catalogs is not None:
                traj = self.catalogs.resolve(ref)
        if traj is None or traj.find("Shape") is None:
            raise EntityError("FollowTrajectoryAction without a trajectory shape",
                              line=fta.sourceline)
        start = e.pose or Pose(0.0, 0.0, 0.0, 0.0)
        path = shape_path(traj.find("Shape"), self.res, start)
        timing = fta.find("TimeReference/Timing")
        h = _fill_heading(path.h, path.tangent)  # the file's headings, else the path's tangent
        if timing is not None and np.isfinite(path.time).all():
            scale, off = attr(timing, "scale", 1.0), attr(timing, "offset", 0.0)
            tt = path.time * scale + off
            if timing.get("domainAbsoluteRelative", "absolute") == "relative":
                tt = tt + self.t
            if np.any(np.diff(tt) < 0):
                raise EntityError(f"trajectory {traj.get('name')!r}: times decrease",
                                  line=traj.sourceline)
            tr = Traj(tt, path.x, path.y, path.z, h, timed=True).fill_gaps()
        else:
            if timing is not None:  # timed, but a vertex has no time: followed at the speed
                untimed = next((v for v in traj.iter("Vertex") if v.get("time") is None), traj)
                report_source("source.openscenario.vertex_without_time",
                              f"entity {e.name!r}: trajectory {traj.get('name')!r} has a "
                              "TimeReference but a vertex without time: followed at the "
                              "entity's speed instead", entity=e.name, line=untimed.sourceline)
            v = e.v
            if abs(v) < 1e-9:
                raise EntityError(
                    f"its trajectory {traj.get('name')!r} has no vertex times (TimeReference "
                    f"{'None' if timing is None else 'without times on every vertex'}) and its "
                    f"speed is 0 when the action starts at t={self.t:g} s: give vertex times or a "
                    "SpeedAction before it", line=fta.sourceline)
            s0 = float(attr(fta, "initialDistanceOffset", 0.0))
            total = float(path.s[-1])
            s0 = min(max(s0, 0.0), total)
            goal = total if v > 0 else 0.0
            dur = abs(goal - s0) / abs(v)
            n = max(int(math.ceil(dur / self.dt)), 1)
            tt = self.t + np.linspace(0.0, dur, n + 1)
            ss = s0 + np.sign(v) * (tt - self.t) * abs(v)
            tr = Traj(tt, np.interp(ss, path.s, path.x), np.interp(ss, path.s, path.y),
                      np.interp(ss, path.s, path.z), np.interp(ss, path.s, np.unwrap(h)),
                      timed=False)
        self._end_traj(e, self.t)
        self._drop_rows_from(e, float(tr.t[0]))
        if tr.timed and e.travelled == 0 and not any(r[0] > 0 for r in e.rows):
            # an entity at rest since its teleport that starts a timed trajectory: OpenSCENARIO's
            # way to spawn it (no spawn time before 1.3; this toolkit's export does it): its
            # recording starts with the trajectory
            e.rows.clear()
        e.traj, e.lane, e.rest_since, e.road_end_since, e.lat = tr, None, None, None, None
        return float(tr.t[-1])

    catalogs = None

    def _end_traj(self, e: Entity, t: float) -> None:
        """Record the samples of ``e``'s trajectory up to ``t`` and leave it."""
        tr = e.traj
        if tr is None:
            return
        keep = tr.t <= t + 1e-9
        for k in np.flatnonzero(keep):
            e.rows.append((float(tr.t[k]), float(tr.x[k]), float(tr.y[k]), float(tr.z[k]),
                           float(tr.h[k]), bool(tr.filled[k])))
        if t < tr.t[-1] - 1e-9 and t > tr.t[0]:
            self._record(e, t, tr.at(t))
        e.pose = tr.at(min(max(t, tr.t[0]), tr.t[-1]))
        k = int(np.searchsorted(tr.t, min(t, tr.t[-1]), side="right"))
        k = min(max(k, 1), len(tr.t) - 1)
        dx, dy = tr.x[k] - tr.x[k - 1], tr.y[k] - tr.y[k - 1]
        e.motion_h = math.atan2(dy, dx) if math.hypot(dx, dy) > 1e-9 else None
        e.traj = None

    def _rest_mark(self, e: Entity, t: float, force: bool = False) -> None:
        if e.pose is None:
            return
        if force or e.rest_since is None:
            self._record(e, t, e.pose)
            e.rest_since = t

    # -- motion ----------------------------------------------------------------------------------
    def _advance(self, e: Entity, t1: float) -> None:
        """Move ``e`` from self.t to t1."""
        if e.pose is None or e.error:
            return
        if e.traj is not None:
            if t1 < e.traj.t[0] - 1e-9:  # absolute times in the future: waiting
                return
            old = e.pose
            e.pose = e.traj.at(min(t1, e.traj.t[-1]))
            e.travelled += math.hypot(e.pose.x - old.x, e.pose.y - old.y)
            if t1 >= e.traj.t[-1] - 1e-9:
                timed = e.traj.timed
                self._end_traj(e, float(e.traj.t[-1]))
                # at rest after a timed trajectory: its vertices were all the file prescribed, the
                # rest is not recorded (as this toolkit's export means it); else it is
                e.rest_since = math.inf if timed and abs(e.v) < 1e-9 and e.ramp is None else None
            return
        v0 = e.v
        if e.ramp is not None:
            a, b, va, vb, shape = e.ramp
            u = min(max((t1 - a) / max(b - a, 1e-9), 0.0), 1.0)
            e.v = va + (vb - va) * _shape(shape, u)
            if u >= 1.0:
                e.ramp = None
        d = 0.5 * (v0 + e.v) * (t1 - self.t)
        if abs(d) < 1e-12 and abs(e.v) < 1e-9:
            self._rest_mark(e, self.t)
            return
        if e.rest_since is not None and e.rest_since < self.t - 1e-9:
            self._record(e, self.t, e.pose)  # the end of a rest
        e.rest_since = None
        self._move_along_lane(e, d, t1)
        e.travelled += abs(d)
        self._record(e, t1, e.pose)

    def _acquire_lane(self, e: Entity) -> None:
        """The road coordinates lane following starts from (``e.lane``; road "" off the roads)."""
        p = e.pose
        if e.lane is None:
            pr = self.net.world_to_road(np.array([p.x]), np.array([p.y]),
                                        None if p.h is None else np.array([p.h]))
            if pr.road_id[0] is None or not np.isfinite(pr.s[0]):
                e.lane = ("", 0.0, 0.0, 0.0, 0.0)
            else:
                rh = float(pr.road_heading[0])
                if e.motion_h is not None:  # go on in the direction the trajectory went
                    direction = (1.0 if math.cos(e.motion_h - rh) >= 0 else -1.0) * (
                        1.0 if e.v >= 0 else -1.0)
                else:
                    direction = 1.0 if math.cos((p.h or rh) - rh) >= 0 else -1.0
                face = 0.0 if math.cos((p.h if p.h is not None else rh) - rh) >= 0 else math.pi
                e.lane = (str(pr.road_id[0]), float(pr.s[0]), float(pr.t[0]), direction, face)
                e.lane_id = int(pr.lane_id[0])

    def _move_along_lane(self, e: Entity, d: float, t1: float) -> None:
        p = e.pose
        self._acquire_lane(e)
        road, s, t, direction, face = e.lane
        if not road:  # off the roads: along the heading (or on in the trajectory's direction)
            h, dd = (e.motion_h, abs(d)) if e.motion_h is not None else (p.h or 0.0, d)
            e.pose = Pose(p.x + dd * math.cos(h), p.y + dd * math.sin(h), p.z, p.h)
            return
        s_new = s + direction * d
        length = self.net.roads[road].length
        if s_new < 0 or s_new > length:
            s_new, e.v, e.ramp = min(max(s_new, 0.0), length), 0.0, None  # end of the road
            if e.road_end_since is None:
                e.road_end_since = self.t
        t_old = t
        if e.lat is not None:  # a lane change under way: t along its shape
            a, b, t_from, t_to, shape = e.lat
            u = min(max((t1 - a) / max(b - a, 1e-9), 0.0), 1.0)
            t = t_from + (t_to - t_from) * _shape(shape, u)
            if u >= 1.0:
                e.lat = None
        x, y, z, hdg = self.net.road_to_world(road, np.array([s_new]), np.array([t]))
        h = float(hdg[0]) + face
        if t != t_old and abs(d) > 1e-9:  # heading along the motion while moving sideways
            h = float(hdg[0]) + math.atan2(t - t_old, direction * d) + (0.0 if d > 0 else math.pi)
        e.pose = Pose(float(x[0]), float(y[0]), float(z[0]), h)
        e.lane = (road, s_new, t, direction, face)

    # -- conditions ------------------------------------------------------------------------------
    def _trigger(self, trig) -> bool:
        if trig is None:
            return True
        groups = trig.findall("ConditionGroup")
        if not groups:
            return False  # an empty trigger never fires (an empty StopTrigger: no stop)
        return any(all(self._condition(c) for c in g.findall("Condition")) for g in groups)

    def _condition(self, c) -> bool:
        now = self._holds(c)
        key = c
        if now and key not in self.cond_true:
            self.cond_true[key] = self.t
            self.wakeups.add(self.t + (attr(c, "delay", 0.0) or 0.0))
        if key not in self.cond_true:
            return False
        return self.t >= self.cond_true[key] + (attr(c, "delay", 0.0) or 0.0) - 1e-9

    def _holds(self, c) -> bool:
        bv = c.find("ByValueCondition")
        if bv is not None:
            k = next((x for x in bv if isinstance(x.tag, str)), None)
            if k is None:
                return False
            if k.tag == "SimulationTimeCondition":
                # "greaterThan v" holds for every t > v: the event starts at v (not one step later)
                rule = "greaterOrEqual" if k.get("rule") == "greaterThan" else k.get("rule")
                self.wakeups.add(attr(k, "value"))
                return _compare(self.t, rule, attr(k, "value"), 1e-9)
            if k.tag == "StoryboardElementStateCondition":
                return self._element_state(k.get("storyboardElementRef"), k.get("state"))
            if k.tag == "ParameterCondition":
                v = self.params.get(k.get("parameterRef"))
                try:
                    return _compare(float(v), k.get("rule"), float(k.get("value")), 1e-9)
                except (TypeError, ValueError):
                    return v == k.get("value") if k.get("rule") == "equalTo" else False
            self.ignored_conditions[k.tag] = self.ignored_conditions.get(k.tag, 0) + 1
            self.ignored_lines.setdefault(k.tag, k.sourceline)
            return False
        be = c.find("ByEntityCondition")
        if be is None:
            return False
        refs = [r.get("entityRef") for r in be.iterfind("TriggeringEntities/EntityRef")]
        rule = be.find("TriggeringEntities")
        k = next((x for x in be.find("EntityCondition") if isinstance(x.tag, str)), None) \
            if be.find("EntityCondition") is not None else None
        if k is None or k.tag not in ENTITY_CONDITIONS:
            tag = k.tag if k is not None else "EntityCondition"
            self.ignored_conditions[tag] = self.ignored_conditions.get(tag, 0) + 1
            self.ignored_lines.setdefault(tag, (k if k is not None else be).sourceline)
            return False
        vals = [self._entity_condition(k, self.ents.get(r)) for r in refs]
        if not vals:
            return False
        return all(vals) if rule is not None and rule.get("triggeringEntitiesRule") == "all" else any(vals)

    def _entity_condition(self, k, e: Entity | None) -> bool:
        if e is None or e.pose is None:
            return False
        p = e.pose
        tag = k.tag
        try:
            if tag == "ReachPositionCondition":
                q = self.res.position(k.find("Position"))
                return math.hypot(p.x - q.x, p.y - q.y) <= attr(k, "tolerance")
            if tag == "SpeedCondition":
                return _compare(e.v, k.get("rule"), attr(k, "value"), 1e-6)
            if tag == "StandStillCondition":
                return abs(e.v) < 1e-3 and e.traj is None
            if tag == "TraveledDistanceCondition":
                return e.travelled >= attr(k, "value")
            if tag == "EndOfRoadCondition":
                return e.road_end_since is not None and self.t - e.road_end_since >= attr(k, "duration")
            if tag == "OffroadCondition":
                on = bool(self.net.world_to_road(np.array([p.x]), np.array([p.y])).on_road[0])
                e.offroad_since = None if on else (e.offroad_since if e.offroad_since is not None
                                                   else self.t)
                return e.offroad_since is not None and self.t - e.offroad_since >= attr(k, "duration")
            other = self.ents.get(k.get("entityRef")) if k.get("entityRef") else None
            if tag == "RelativeSpeedCondition":
                return other is not None and _compare(e.v - other.v, k.get("rule"), attr(k, "value"), 1e-6)
            if other is not None and other.pose is not None:
                q, qlen = other.pose, other.length
            elif k.find("Position") is not None:
                q, qlen = self.res.position(k.find("Position")), 0.0
            else:
                return False
            dist = math.hypot(p.x - q.x, p.y - q.y)
            if k.get("freespace") == "true":
                dist = max(dist - 0.5 * (e.length + qlen), 0.0)
            if tag in ("DistanceCondition", "RelativeDistanceCondition"):
                return _compare(dist, k.get("rule"), attr(k, "value"), 1e-6)
            if tag == "TimeHeadwayCondition":
                return abs(e.v) > 1e-6 and _compare(dist / abs(e.v), k.get("rule"), attr(k, "value"), 1e-6)
            if tag == "TimeToCollisionCondition":
                ov = other.v if other is not None else 0.0
                closing = e.v - ov
                return closing > 1e-6 and _compare(dist / closing, k.get("rule"), attr(k, "value"), 1e-6)
        except ShapeError:
            return False
        return False

    def _element_state(self, name: str | None, state: str | None) -> bool:
        el = self.named.get(name or "")
        if el is None:
            return False
        st = self.state.get(el)
        if st is None:
            return state == "standbyState"
        _, start, end = st
        if state in ("startTransition", "runningState"):
            return start is not None and (state == "startTransition" or end is None or self.t < end)
        if state in ("endTransition", "completeState"):
            return end is not None and self.t >= end - 1e-9
        return False

    # -- the storyboard --------------------------------------------------------------------------
    def run(self) -> dict[str, Entity]:
        sb = self.root.find("Storyboard")
        if sb is None:
            raise FormatError("no <Storyboard>")
        init = sb.find("Init/Actions")
        if init is not None:
            privs = list(init.iterfind("Private"))
            order = {"TeleportAction": 0, "LongitudinalAction": 1}
            todo = [(order.get(next((c.tag for c in pa if isinstance(c.tag, str)), ""), 2), e, pa)
                    for pr in privs for e in [self.ents.get(pr.get("entityRef"))] if e is not None
                    for pa in pr.iterfind("PrivateAction")]
            for _, e, pa in sorted(todo, key=lambda x: x[0]):
                self._private(e, pa)
        acts = [a for story in sb.iterfind("Story") for a in story.iterfind("Act")]
        events = {a: [(mg, ev) for mg in a.iterfind("ManeuverGroup")
                          for ev in mg.iterfind("Maneuver/Event")] for a in acts}
        stop = sb.find("StopTrigger")
        done_at: float | None = None
        has_stop = stop is not None and stop.find("ConditionGroup") is not None
        # a stop at a simulation time is waited for (up to max_duration), whatever else ended
        stop_time = max([attr(c, "value") for c in stop.iter("SimulationTimeCondition")], default=0.0) \
            if has_stop else 0.0
        while True:
            for a in acts:
                if a not in self.state and self._trigger(a.find("StartTrigger")):
                    self.state[a] = ("act", self.t, None)
            for a in acts:
                if a not in self.state:
                    continue
                for mg, ev in events[a]:
                    if ev in self.state or not self._trigger(ev.find("StartTrigger")):
                        continue
                    self._start_event(mg, ev)
            self._update_ends(acts, events)
            if has_stop and self._trigger(stop):
                break
            busy = any(e.traj is not None for e in self.ents.values() if not e.error)
            done = all(self.state.get(a, (None, None, None))[2] is not None for a in acts)
            if done and not busy:
                done_at = self.t if done_at is None else done_at
            else:
                done_at = None
            if (done_at is not None and (not has_stop or (self.t >= done_at + GRACE
                                                         and self.t >= stop_time))) \
                    or self.t >= self.max_duration:
                break
            # the next step, or earlier where a trajectory or ramp ends or a condition fires between
            # steps (events chained to an end start then, not at the next step)
            soon = [w for w in self.wakeups if w > self.t + 1e-6]
            soon += [float(e.traj.t[-1]) for e in self.ents.values()
                     if e.traj is not None and e.traj.t[-1] > self.t + 1e-6]
            soon += [e.ramp[1] for e in self.ents.values() if e.ramp is not None and e.ramp[1] > self.t + 1e-6]
            t1 = min([self.t + self.dt, *soon])
            for e in self.ents.values():
                self._advance(e, t1)
            self.t = round(t1, 9)
        for e in self.ents.values():
            if e.traj is not None and e.traj.timed:
                late = int(np.sum(e.traj.t > self.t + 1e-9))
                if late:
                    self.clipped[e.name] = late
            self._end_traj(e, self.t)
            if e.pose is not None and e.rest_since is not None and e.rest_since < self.t - 1e-9:
                self._record(e, self.t, e.pose)
        return self.ents

    def _start_event(self, mg, ev) -> None:
        actors = [r.get("entityRef") for r in mg.iterfind("Actors/EntityRef")]
        end = self.t
        for action in ev.iterfind("Action"):
            a_end = self.t
            pa = action.find("PrivateAction")
            if pa is not None:
                for name in actors:
                    e = self.ents.get(name)
                    if e is not None and not e.error:
                        a_end = max(a_end, self._private(e, pa))
            else:
                kind = next((c.tag for c in action if isinstance(c.tag, str)), "Action")
                self.ignored_actions[kind] = self.ignored_actions.get(kind, 0) + 1
                self.ignored_lines.setdefault(kind, action.sourceline)
            self.state[action] = ("action", self.t, a_end)
            end = max(end, a_end)
        self.state[ev] = ("event", self.t, end)

    def _update_ends(self, acts, events) -> None:
        """Acts, maneuver groups and maneuvers end when all their events have ended."""
        if not hasattr(self, "_groups"):  # (element, its events) of every group, once
            self._groups = {a: [(m, list(m.iter("Event"))) for mg in a.iterfind("ManeuverGroup")
                                for m in [mg, *mg.iterfind("Maneuver")]] for a in acts}
        for a in acts:
            st = self.state.get(a)
            if st is None or st[2] is not None:
                continue
            ends = [self.state.get(ev, (None, None, None))[2] for _, ev in events[a]]
            if all(x is not None and x <= self.t + 1e-9 for x in ends):
                self.state[a] = ("act", st[1], max([st[1], *ends]))
            for m, evs in self._groups[a]:
                if m in self.state:
                    continue
                es = [self.state.get(ev, (None, None, None))[2] for ev in evs]
                if es and all(x is not None and x <= self.t + 1e-9 for x in es):
                    self.state[m] = ("group", None, max(es))


def _shape(shape: str, u: float) -> float:
    """The OpenSCENARIO dynamics shapes on [0, 1] (step: at once)."""
    if shape == "step":
        return 1.0
    return {"linear": u, "cubic": 3 * u * u - 2 * u ** 3,
            "sinusoidal": 0.5 - 0.5 * math.cos(math.pi * u)}.get(shape, u)


def _fill_heading(h: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(h), h, tangent)


def _compare(a: float, rule: str | None, b: float, tol: float) -> bool:
    if rule == "greaterThan":
        return a > b
    if rule == "lessThan":
        return a < b
    if rule == "greaterOrEqual":
        return a >= b - tol
    if rule == "lessOrEqual":
        return a <= b + tol
    if rule == "notEqualTo":
        return abs(a - b) > tol
    return abs(a - b) <= tol  # equalTo
