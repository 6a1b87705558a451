"""Scenes with known truth for the criticality measures (docs/derive.md "Against the truth").

- :func:`traffic_scene`: lane-keeping traffic on a straight multi-lane highway — each lane's
  vehicles follow one smooth speed profile, shifted in time, so every same-lane net time headway
  stays at or above ``min_headway_s`` (1.8 s) while followers close in and fall back; drivers
  wander a little in their lanes. It holds no critical situation. ``conflicts`` plants cut-ins
  and hard braking into it (the background vehicles that come near a planted one are left out).
- :func:`conflict_scene`: one true conflict — ``cut_in``, ``hard_braking`` (highway), ``crossing``
  (two vehicles at a junction, one brakes late), ``pedestrian`` (a vehicle brakes for a pedestrian
  crossing) — with lane-keeping vehicles around it, whose true minimum TTC is ``min_ttc`` by
  construction (a scene parameter is solved for it on the noise-free motion).

Every scene is measured as an acquisition ``method`` would (:data:`METHODS`: aerial footage at
25 Hz with 0.1-0.3 m position noise, infrastructure LiDAR at 10 Hz with 0.05-0.2 m, a simulator
at 10 Hz without noise); the noise is Gaussian and white and the recording declares it (``_std``
columns; velocities ``VELOCITY_STD_PER_M`` times the position std, sizes 0.1 / 0.05 m). The
same ``seed`` with ``position_std=0`` gives the same motion without noise (the truth as a
recording). ``return_truth`` adds the noise-free states and the planted conflicts: participants,
kind and designed minimum TTC with its time.

The design TTC follows the derivations' definitions (docs/derive.md): along the lane,
``gap / closing speed``, while both reference points are in one lane; otherwise the first contact
of the footprints at constant velocity, here for footprints aligned with the axes (the scenes'
headings are 0 or 90° up to the lane change's few degrees).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: acquisition methods: recording method, sampling rate (Hz), default position std (m) and heading
#: std (rad)
METHODS: dict[str, dict] = {
    "aerial": {"method": "aerial", "rate_hz": 25.0, "position_std": 0.2, "heading_std": 0.02},
    "lidar": {"method": "infrastructure_lidar", "rate_hz": 10.0, "position_std": 0.1,
              "heading_std": 0.03},
    "simulator": {"method": "traffic_simulation", "rate_hz": 10.0, "position_std": 0.0,
                  "heading_std": 0.0},
}
#: declared (and applied) velocity std per metre of position std: a tracker's velocity from
#: differenced positions
VELOCITY_STD_PER_M = 2.0
#: the kinds of :func:`conflict_scene`
CONFLICT_KINDS = ("cut_in", "hard_braking", "crossing", "pedestrian")
HIGHWAY_KINDS = ("cut_in", "hard_braking")
LANE_W = 3.5
#: lane centres (y, m) of the highway's right lanes -1 (left, fast) .. -3 (right, slow)
LANE_Y = {-1: -1.75, -2: -5.25, -3: -8.75}
#: the internal time step (s) of the motion, a divisor of every method's sampling step
FINE_DT = 0.005
#: recording.json thresholds of every scene (as the sample highway's)
THRESHOLDS = {"ttc_s": 3.0, "pet_s": 1.5, "thw_s": 1.0}


@dataclass
class _Mover:
    """One participant's true motion on the fine time grid ``t``: along the direction ``theta``
    from ``origin`` by ``s`` (speed ``v``, acceleration ``a``) and sideways by ``d`` (``dd``,
    ``ddd``: its derivatives)."""

    cls: str
    length: float
    width: float
    t: np.ndarray
    s: np.ndarray
    v: np.ndarray
    a: np.ndarray
    d: np.ndarray
    dd: np.ndarray
    ddd: np.ndarray
    origin: tuple[float, float] = (0.0, 0.0)
    theta: float = 0.0
    role: str = "background"

    def xy(self) -> dict[str, np.ndarray]:
        c, sn = np.cos(self.theta), np.sin(self.theta)
        x0, y0 = self.origin
        return {"x": x0 + self.s * c - self.d * sn, "y": y0 + self.s * sn + self.d * c,
                "vx": self.v * c - self.dd * sn, "vy": self.v * sn + self.dd * c,
                "ax": self.a * c - self.ddd * sn, "ay": self.a * sn + self.ddd * c,
                "heading": self.theta + np.arctan2(self.dd, np.maximum(self.v, 1e-9))}


@dataclass
class _Scene:
    movers: list[_Mover] = field(default_factory=list)
    conflicts: list[dict] = field(default_factory=list)


def _fine_grid(duration_s: float) -> np.ndarray:
    return np.arange(int(round(duration_s / FINE_DT)) + 1) * FINE_DT


def _speed_profile(t: np.ndarray, v0: float, phases: list[tuple[float, float, float]]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, v, a)`` on the fine grid ``t`` of a motion from speed ``v0`` whose acceleration
    ramps linearly to each phase's value ``a`` from its start over ``ramp`` s (phases ``(start,
    a, ramp)`` in time order); a vehicle that reaches speed 0 stops (its braking ends) until a
    later phase accelerates it."""
    a_cmd = np.zeros(len(t))
    prev = 0.0
    for start, a, ramp in phases:
        w = np.clip((t - start) / max(ramp, FINE_DT), 0.0, 1.0)
        a_cmd = np.where(t >= start, prev + (a - prev) * w, a_cmd)
        prev = a
    v = np.empty(len(t))
    acc = np.empty(len(t))
    cur = float(v0)
    for k in range(len(t)):  # the scene's few participants; a stop is a state
        ak = a_cmd[k] if (cur > 0.0 or a_cmd[k] > 0.0) else 0.0
        v[k], acc[k] = cur, ak
        cur = max(cur + ak * FINE_DT, 0.0)
    s = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * FINE_DT)]
    return s, v, acc


def _lane_change(t: np.ndarray, d0: float, shift: float, start: float, dur: float):
    """Lateral offset and its two derivatives of a cosine lane change by ``shift`` m."""
    u = np.clip((t - start) / dur, 0.0, 1.0)
    inside = (u > 0) & (u < 1)
    d = d0 + shift * 0.5 * (1 - np.cos(np.pi * u))
    dd = np.where(inside, shift * 0.5 * np.pi / dur * np.sin(np.pi * u), 0.0)
    ddd = np.where(inside, shift * 0.5 * (np.pi / dur) ** 2 * np.cos(np.pi * u), 0.0)
    return d, dd, ddd


def _box_ttc(dx, dy, wx, wy, hx, hy) -> np.ndarray:
    """First contact time of two footprints aligned with the axes at constant velocity: relative
    position ``(dx, dy)``, relative velocity ``(wx, wy)``, summed half extents ``(hx, hy)``
    (0 if they overlap now, inf if never)."""
    lo, hi = np.zeros(np.shape(dx)), np.full(np.shape(dx), np.inf)
    never = np.zeros(np.shape(dx), bool)
    for d, w, h in ((dx, wx, hx), (dy, wy, hy)):
        with np.errstate(divide="ignore", invalid="ignore"):
            a, b = (-h - d) / w, (h - d) / w
        still = w == 0
        never |= still & (np.abs(d) > h)
        lo = np.maximum(lo, np.where(still, -np.inf, np.minimum(a, b)))
        hi = np.minimum(hi, np.where(still, np.inf, np.maximum(a, b)))
    hit = ~never & (lo <= hi) & (hi >= 0)
    return np.where(hit, np.maximum(lo, 0.0), np.inf)


def _extent(m: _Mover) -> tuple[float, float]:
    """Half extents along x and y of a mover aligned with the axes."""
    along = abs(np.cos(m.theta)) > 0.5
    return (m.length / 2, m.width / 2) if along else (m.width / 2, m.length / 2)


def design_ttc(a: _Mover, b: _Mover, lanes: bool = True) -> np.ndarray:
    """TTC of the pair over the fine grid as the derivations define it (module docstring):
    ``gap / closing`` along x while both are in one lane of the highway (``lanes``), else the
    first contact of the axis-aligned footprints at constant velocity."""
    p, q = a.xy(), b.xy()
    (ax_, ay_), (bx_, by_) = _extent(a), _extent(b)
    box = _box_ttc(q["x"] - p["x"], q["y"] - p["y"], q["vx"] - p["vx"], q["vy"] - p["vy"],
                   ax_ + bx_, ay_ + by_)
    if not lanes:
        return box
    la, lb = (np.floor(-m["y"] / LANE_W) for m in (p, q))
    same = la == lb
    ahead = q["x"] >= p["x"]
    gap = np.abs(q["x"] - p["x"]) - 0.5 * (a.length + b.length)
    closing = np.where(ahead, p["vx"] - q["vx"], q["vx"] - p["vx"])
    with np.errstate(divide="ignore", invalid="ignore"):
        lane = np.where(closing > 0, np.maximum(gap, 0.0) / closing, np.inf)
    return np.where(same, lane, box)


def _solve(fn, target: float, lo: float, hi: float, iters: int = 40) -> float:
    """The parameter in ``[lo, hi]`` where the increasing ``fn`` reaches ``target`` (bisection)."""
    for _ in range(iters):
        mid = 0.5 * (lo + hi)
        if fn(mid) < target:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def _car(rng: np.random.Generator) -> tuple[float, float]:
    return float(np.clip(rng.normal(4.6, 0.3), 3.8, 5.4)), float(np.clip(rng.normal(1.85, 0.08),
                                                                         1.65, 2.05))


def _straight(t, cls, size, v0, phases, origin, theta, lateral=None, role="background") -> _Mover:
    s, v, a = _speed_profile(t, v0, phases)
    d, dd, ddd = lateral if lateral is not None else (np.zeros(len(t)),) * 3
    return _Mover(cls, size[0], size[1], t, s, v, a, d, dd, ddd, origin, theta, role)


# --- the conflicts ------------------------------------------------------------------------------

def _hard_braking(rng, t, min_ttc: float, x0: float, t0: float) -> list[_Mover]:
    """A leader brakes hard, its follower reacts late; the initial gap is solved for."""
    v0 = rng.uniform(22.0, 30.0)
    tb = t0 + 3.0
    aL, durL = -rng.uniform(5.0, 7.0), rng.uniform(1.5, 2.5)
    aF, react = -rng.uniform(5.5, 7.5), rng.uniform(0.7, 1.2)
    sizes = (_car(rng), _car(rng))
    lead_phases = [(tb, aL, 0.4), (tb + durL, 0.0, 0.4)]
    v_end = max(v0 + aL * durL, 0.0)
    # the follower brakes until it is 1.5 m/s slower than the leader, then holds its speed
    t_hold = tb + react + (v0 - max(v_end - 1.5, 0.0)) / -aF
    fol_phases = [(tb + react, aF, 0.4), (t_hold, 0.0, 0.4)]
    y = LANE_Y[-2]

    def movers(gap: float) -> list[_Mover]:
        lead = _straight(t, "car", sizes[0], v0, lead_phases, (x0 + gap + 0.5 * (
            sizes[0][0] + sizes[1][0]), y), 0.0, role="leader")
        fol = _straight(t, "car", sizes[1], v0, fol_phases, (x0, y), 0.0, role="follower")
        return [fol, lead]

    def min_ttc_of(gap: float) -> float:
        f, le = movers(gap)
        return float(design_ttc(f, le).min())

    gap = _solve(min_ttc_of, min_ttc, 2.0, 120.0)
    return movers(gap)


def _cut_in(rng, t, min_ttc: float, x0: float, t0: float) -> list[_Mover]:
    """A slower car changes from the left lane into the ego's lane just ahead of it; the ego
    brakes after a reaction time; the gap at the lane change's start is solved for."""
    vE = rng.uniform(27.0, 33.0)
    vC = vE - rng.uniform(4.0, 8.0)
    t_lc, dur = t0 + 3.0, rng.uniform(2.5, 4.0)
    react, aE = rng.uniform(0.5, 1.0), -rng.uniform(3.0, 5.0)
    t_brake = t_lc + 0.5 * dur + react
    t_hold = t_brake + (vE - (vC - 0.5)) / -aE
    sizes = (_car(rng), _car(rng))
    lat = _lane_change(t, 0.0, LANE_Y[-2] - LANE_Y[-1], t_lc, dur)

    def movers(gap: float) -> list[_Mover]:
        ego = _straight(t, "car", sizes[0], vE, [(t_brake, aE, 0.5), (t_hold, 0.0, 0.5)],
                        (x0, LANE_Y[-2]), 0.0, role="ego")
        # the cutter's start so that the net gap at t_lc is `gap`
        k = int(round(t_lc / FINE_DT))
        xc = x0 + ego.s[k] - vC * t[k] + gap + 0.5 * (sizes[0][0] + sizes[1][0])
        cut = _straight(t, "car", sizes[1], vC, [], (xc, LANE_Y[-1]), 0.0, lateral=lat,
                        role="cutter")
        return [ego, cut]

    def min_ttc_of(gap: float) -> float:
        e, c = movers(gap)
        return float(design_ttc(e, c)[t >= t0].min())

    gap = _solve(min_ttc_of, min_ttc, 0.5, 80.0)
    return movers(gap)


def _crossing(rng, t, min_ttc: float, t0: float, pedestrian: bool) -> list[_Mover]:
    """A vehicle eastbound on road 1 (lane -1) and, on a collision course at constant speed, a
    vehicle northbound on road 2 (which yields: it brakes, waits until the other has passed and
    goes on) or a pedestrian crossing road 1 west of the junction (the vehicle yields); the
    moment the yielding one brakes is solved for."""
    veh, vA = _car(rng), rng.uniform(8.0, 13.0)
    T = t0 + 6.0  # the undisturbed meeting time of both centres
    a_brake = -rng.uniform(5.0, 7.0)
    yA = LANE_Y[-1]
    if pedestrian:
        size, vB, xc = (0.5, 0.6), rng.uniform(1.1, 1.6), -25.0
        t_go = T + (veh[1] / 2 + 0.8) / vB  # the pedestrian has left the vehicle's lane

        def movers(tb: float) -> list[_Mover]:
            a = _straight(t, "car", veh, vA, [(tb, a_brake, 0.3), (max(t_go, tb + 0.3), 2.0, 0.5)],
                          (xc - vA * T, yA), 0.0, role="yielding")
            b = _straight(t, "pedestrian", size, vB, [], (xc, yA - vB * T), np.pi / 2,
                          role="crossing")
            return [a, b]
    else:
        size, vB, xc = _car(rng), rng.uniform(8.0, 13.0), -LANE_Y[-1]
        t_go = T + (veh[0] / 2 + 3.0) / vA  # the crossing car's rear has passed

        def movers(tb: float) -> list[_Mover]:
            a = _straight(t, "car", veh, vA, [], (xc - vA * T, yA), 0.0, role="crossing")
            b = _straight(t, "car", size, vB, [(tb, a_brake, 0.3), (max(t_go, tb + 0.3), 2.0, 0.5)],
                          (xc, yA - vB * T), np.pi / 2, role="yielding")
            return [a, b]

    def min_ttc_of(tb: float) -> float:
        a, b = movers(tb)
        return float(design_ttc(a, b, lanes=False)[t >= t0].min())

    # the later the braking, the smaller the minimum TTC: solve on its negation
    tb = _solve(lambda x: -min_ttc_of(x), -min_ttc, t0 + 0.5, T)
    out = movers(tb)
    p, q = (m.xy() for m in out)
    (ax_, ay_), (bx_, by_) = (_extent(m) for m in out)
    clear = np.maximum(np.abs(q["x"] - p["x"]) - ax_ - bx_, np.abs(q["y"] - p["y"]) - ay_ - by_)
    if clear.min() <= 0.05:  # the yielding one could not avoid contact
        raise _Redraw
    return out


class _Redraw(Exception):
    """A drawn conflict's design failed (contact): draw its parameters again."""


# --- the scenes -----------------------------------------------------------------------------------

def _background(rng, t, lanes: tuple[int, ...], length_m: float, duration_s: float,
                min_headway_s: float, speeds: dict[int, float]) -> list[_Mover]:
    """Lane-keeping traffic (module docstring): per lane one speed profile shifted in time."""
    out = []
    for lane in lanes:
        V = speeds[lane]
        amp = rng.uniform(0.4, 0.9, 2)
        per = rng.uniform(25.0, 80.0, 2)
        ph = rng.uniform(0, 2 * np.pi, 2)
        vmin, vmax = V - amp.sum(), V + amp.sum()

        def X(u, V=V, amp=amp, per=per, ph=ph):
            w = 2 * np.pi / per
            return V * u - ((amp / w)[:, None] * (np.cos(w[:, None] * u + ph[:, None])
                                                  - np.cos(ph[:, None]))).sum(0)

        def dX(u, V=V, amp=amp, per=per, ph=ph):
            w = 2 * np.pi / per
            return V + (amp[:, None] * np.sin(w[:, None] * u + ph[:, None])).sum(0)

        def ddX(u, amp=amp, per=per, ph=ph):
            w = 2 * np.pi / per
            return (amp[:, None] * w[:, None] * np.cos(w[:, None] * u + ph[:, None])).sum(0)

        tau = -(length_m / vmin) - 5.0
        prev_len = None
        while tau < duration_s:
            truck = lane == -3 and rng.random() < 0.3
            size = ((float(rng.uniform(10.0, 16.5)), 2.5) if truck else _car(rng))
            if prev_len is not None:
                tau += (min_headway_s * vmax / vmin + 0.5 * (prev_len + size[0]) / vmin + 0.05
                        + rng.exponential(1.5))
            prev_len = size[0]
            u = t - tau
            s, v, a = X(u), dX(u), ddX(u)
            if not ((s >= 0) & (s <= length_m)).any():
                continue
            wa, wp, wph = rng.uniform(0.0, 0.2), rng.uniform(8.0, 25.0), rng.uniform(0, 2 * np.pi)
            w = 2 * np.pi / wp
            d = wa * np.sin(w * t + wph)
            out.append(_Mover("truck" if truck else "car", size[0], size[1], t, s, v, a, d,
                              wa * w * np.cos(w * t + wph), -wa * w * w * np.sin(w * t + wph),
                              (0.0, LANE_Y[lane]), 0.0))
    return out


def _near(a: _Mover, b: _Mover, dist: float, length_m: float) -> bool:
    """Whether ``a`` comes within ``dist`` m of ``b`` while both are on the road."""
    p, q = a.xy(), b.xy()
    on = (p["x"] >= 0) & (p["x"] <= length_m) & (q["x"] >= 0) & (q["x"] <= length_m)
    return bool((on & (np.hypot(p["x"] - q["x"], p["y"] - q["y"]) < dist)).any())


def _highway_xodr(length_m: float, lanes: int) -> str:
    from aveas_format.opendrive.builder import straight_highway
    from aveas_format.sample import SITE_CRS

    return straight_highway(length=length_m, lanes_right=lanes, lanes_left=0, lane_width=LANE_W,
                            geo_reference=SITE_CRS)


def _junction_xodr(half: float = 120.0) -> str:
    """Two two-lane roads crossing at the origin: road 1 west to east, road 2 south to north."""
    from aveas_format.opendrive import load_map
    from aveas_format.opendrive.builder import roads_xodr, straight_highway
    from aveas_format.sample import SITE_CRS

    r1 = load_map(straight_highway(2 * half, 1, 1, LANE_W, -half, 0.0, 0.0,
                                   road_id="1").encode()).roads["1"]
    r2 = load_map(straight_highway(2 * half, 1, 1, LANE_W, 0.0, -half, np.pi / 2,
                                   road_id="2").encode()).roads["2"]
    return roads_xodr([r1, r2], name="crossing", geo_reference=SITE_CRS)


def _record(scene: _Scene, xodr: str, *, method: str, position_std: float | None, rate_hz,
            seed: int, duration_s: float, title: str, bounds, return_truth: bool,
            recording_id: str):
    """The recording of ``scene`` as ``method`` measures it (module docstring)."""
    import shapely

    from aveas_format.mapref.build import build_recording

    m = METHODS[method]
    rate = float(rate_hz or m["rate_hz"])
    step = int(round(1.0 / (rate * FINE_DT)))
    sp = m["position_std"] if position_std is None else float(position_std)
    sv, sh = VELOCITY_STD_PER_M * sp, (m["heading_std"] if sp > 0 else 0.0)
    noise = np.random.default_rng([seed, 1])
    x0, y0, x1, y1 = bounds
    rows: dict[str, list] = {k: [] for k in ("participant_id", "time", "x", "y", "vx", "vy", "ax",
                                             "ay", "heading")}
    parts: dict[str, list] = {k: [] for k in ("participant_id", "source_id", "class", "length",
                                              "width", "height", "length_std", "width_std")}
    size_sd = (0.1, 0.05) if sp > 0 else (0.0, 0.0)
    pid = 0
    for mv in scene.movers:
        q = mv.xy()
        k = np.arange(0, len(mv.t), step)
        inside = ((q["x"][k] >= x0) & (q["x"][k] <= x1) & (q["y"][k] >= y0) & (q["y"][k] <= y1))
        if inside.sum() < 3:
            mv.role = "unseen"
            continue
        k = k[inside]
        mv.pid = pid  # type: ignore[attr-defined]
        rows["participant_id"].append(np.full(len(k), pid, np.int64))
        rows["time"].append(np.round(mv.t[k], 6))
        for c in ("x", "y", "vx", "vy", "ax", "ay", "heading"):
            rows[c].append(q[c][k])
        parts["participant_id"].append(pid)
        parts["source_id"].append(f"{mv.role}-{pid}")
        parts["class"].append(mv.cls)
        parts["length"].append(mv.length + noise.normal(0, size_sd[0]))
        parts["width"].append(mv.width + noise.normal(0, size_sd[1]))
        parts["height"].append({"car": 1.5, "truck": 3.8, "pedestrian": 1.75}[mv.cls])
        parts["length_std"].append(size_sd[0])
        parts["width_std"].append(size_sd[1])
        pid += 1
    truth = {k: np.concatenate(v) for k, v in rows.items()}
    n = len(truth["time"])
    states = {"participant_id": truth["participant_id"], "time": truth["time"]}
    for c, sd in (("x", sp), ("y", sp), ("vx", sv), ("vy", sv), ("heading", sh)):
        states[c] = truth[c] + (noise.normal(0, sd, n) if sd > 0 else 0.0)
        states[f"{c}_std"] = np.full(n, sd)
    states["heading"] = np.angle(np.exp(1j * states["heading"]))
    states["xy_corr"] = np.zeros(n, np.float32)
    coverage = shapely.box(x0, y0, x1, y1)
    rec = build_recording(
        map_source=xodr, participants=parts, states=states, method=m["method"],
        partner="aveas-format sample data", start_time="2024-05-13T08:15:00Z",
        nominal_rate_hz=rate, duration_s=duration_s, recording_id=recording_id,
        source={"converter": "aveas_format.sample.scenes", "converter_version": "1", "inputs": [],
                "options": {"method": method, "position_std": sp, "seed": seed}},
        title=title, coverage=coverage.wkt, thresholds=THRESHOLDS,
        rights={"right_of_use": "research_only", "license": "CC-BY-4.0",
                "owner": "aveas-format sample data"})
    if not return_truth:
        return rec
    conflicts = []
    for c in scene.conflicts:
        a, b = c.pop("movers")
        if getattr(a, "pid", None) is None or getattr(b, "pid", None) is None:
            continue
        conflicts.append({**c, "participants": (a.pid, b.pid)})
    return rec, {"states": truth, "conflicts": conflicts, "position_std": sp}


def _plant(rng, t, kind: str, min_ttc: float, x0: float, t0: float) -> list[_Mover]:
    for _ in range(20):
        try:
            if kind == "cut_in":
                return _cut_in(rng, t, min_ttc, x0, t0)
            if kind == "hard_braking":
                return _hard_braking(rng, t, min_ttc, x0, t0)
            return _crossing(rng, t, min_ttc, t0, pedestrian=kind == "pedestrian")
        except _Redraw:
            continue
    raise ValueError(f"cannot design a {kind} conflict with minimum TTC {min_ttc} s")


def _conflict_record(kind: str, movers: list[_Mover], t: np.ndarray, t0: float) -> dict:
    a, b = movers
    ttc = design_ttc(a, b, lanes=kind in HIGHWAY_KINDS)
    ttc = np.where(t >= t0, ttc, np.inf)
    k = int(np.argmin(ttc))
    return {"kind": kind, "min_ttc": float(ttc[k]), "time_of_min": float(t[k]), "movers": movers}


def traffic_scene(duration_s: float = 60.0, *, conflicts: tuple = (), method: str = "aerial",
                  position_std: float | None = None, rate_hz: float | None = None,
                  length_m: float = 1500.0, lanes: int = 3, min_headway_s: float = 1.8,
                  seed: int = 0, return_truth: bool = False):
    """Lane-keeping highway traffic (module docstring) of ``duration_s``, measured as ``method``;
    ``conflicts``: ``(kind, min_ttc)`` of highway kinds (``cut_in``, ``hard_braking``) planted at
    evenly spaced times (a conflict needs ~12 s; background vehicles that come within 80 m of a
    planted one are left out)."""
    if lanes not in (2, 3):
        raise ValueError("lanes: 2 or 3")
    if method not in METHODS:
        raise ValueError(f"method: one of {', '.join(METHODS)}")
    rng = np.random.default_rng([seed, 0])
    t = _fine_grid(duration_s)
    lane_ids = (-1, -2, -3)[:lanes]
    scene = _Scene(_background(rng, t, lane_ids, length_m, duration_s, min_headway_s,
                               {-1: 33.0, -2: 28.0, -3: 24.0}))
    planted: list[_Mover] = []
    for k, (kind, ttc) in enumerate(conflicts):
        if kind not in HIGHWAY_KINDS:
            raise ValueError(f"traffic_scene plants {', '.join(HIGHWAY_KINDS)}; {kind!r} needs "
                             "conflict_scene")
        t0 = max(duration_s * (k + 0.5) / len(conflicts) - 4.0, 0.0)
        # the manoeuvre (at t0 + 3 s) about 40 % into the road
        movers = _plant(rng, t, kind, float(ttc), 0.4 * length_m - 28.0 * (t0 + 3.0), t0)
        rec_c = _conflict_record(kind, movers, t, t0)
        scene.conflicts.append(rec_c)
        planted += movers
    scene.movers = [m for m in scene.movers
                    if not any(_near(m, p, 80.0, length_m) for p in planted)] + planted
    return _record(scene, _highway_xodr(length_m, lanes), method=method,
                   position_std=position_std, rate_hz=rate_hz, seed=seed, duration_s=duration_s,
                   title=f"Lane-keeping traffic on a {lanes}-lane motorway, {duration_s:g} s"
                   + (f", {len(conflicts)} planted conflicts" if conflicts else ""),
                   bounds=(0.0, -lanes * LANE_W, length_m, 0.0), return_truth=return_truth,
                   recording_id=f"traffic-{method}-{seed}")


def conflict_scene(kind: str, min_ttc: float = 1.2, *, method: str = "aerial",
                   position_std: float | None = None, rate_hz: float | None = None,
                   seed: int = 0, return_truth: bool = False):
    """One true conflict of ``kind`` (:data:`CONFLICT_KINDS`) with true minimum TTC ``min_ttc``
    and lane-keeping vehicles around it, measured as ``method`` (module docstring); ~16 s."""
    if kind not in CONFLICT_KINDS:
        raise ValueError(f"kind: one of {', '.join(CONFLICT_KINDS)}")
    if method not in METHODS:
        raise ValueError(f"method: one of {', '.join(METHODS)}")
    rng = np.random.default_rng([seed, 2, CONFLICT_KINDS.index(kind)])
    duration = 20.0
    t = _fine_grid(duration)
    t0 = 6.0 if kind not in HIGHWAY_KINDS else 2.0
    movers = _plant(rng, t, kind, float(min_ttc), 60.0, t0)
    scene = _Scene(conflicts=[_conflict_record(kind, movers, t, t0)])
    if kind in HIGHWAY_KINDS:
        length = 700.0
        back = _background(rng, t, (-1, -2, -3), length, duration, 1.8,
                           {-1: 33.0, -2: 28.0, -3: 24.0})
        scene.movers = [m for m in back if not any(_near(m, p, 60.0, length) for p in movers)]
        scene.movers += movers
        xodr, bounds = _highway_xodr(length, 3), (0.0, -3 * LANE_W, length, 0.0)
    else:
        # a car each on the other arms, through the junction seconds before the conflict
        others = [_straight(t, "car", _car(rng), v, [], origin, theta) for v, origin, theta in (
            (10.0, (10.0 * (t0 - 3.0), -LANE_Y[-1]), np.pi),
            (10.0, (LANE_Y[-1], 10.0 * t0), -np.pi / 2))]
        scene.movers = others + movers
        xodr, bounds = _junction_xodr(), (-120.0, -120.0, 120.0, 120.0)
    return _record(scene, xodr, method=method, position_std=position_std, rate_hz=rate_hz,
                   seed=seed, duration_s=duration, title=f"A {kind.replace('_', ' ')} conflict "
                   f"(true minimum TTC {min_ttc:g} s)", bounds=bounds, return_truth=return_truth,
                   recording_id=f"{kind}-{method}-{seed}")


def _clearance(a: _Mover, b: _Mover) -> np.ndarray:
    """Signed distance of two footprints aligned with the axes over the fine grid (negative: the
    depth by which they overlap)."""
    p, q = a.xy(), b.xy()
    (ax_, ay_), (bx_, by_) = _extent(a), _extent(b)
    gx = np.abs(q["x"] - p["x"]) - ax_ - bx_
    gy = np.abs(q["y"] - p["y"]) - ay_ - by_
    outside = np.hypot(np.maximum(gx, 0.0), np.maximum(gy, 0.0))
    return np.where((gx < 0) & (gy < 0), np.maximum(gx, gy), outside)


def close_pass_scene(margin_m: float = 0.3, *, method: str = "aerial",
                     position_std: float | None = None, rate_hz: float | None = None,
                     seed: int = 0, return_truth: bool = False):
    """Two vehicles crossing paths at the junction at constant speed, the second passing behind
    the first with a true closest clearance of ``margin_m`` m between the footprints (negative:
    they collide, by that depth); measured as ``method``. The encounters of the collision
    probability's calibration (docs/derive.md)."""
    if method not in METHODS:
        raise ValueError(f"method: one of {', '.join(METHODS)}")
    rng = np.random.default_rng([seed, 3])
    t = _fine_grid(16.0)
    T = 8.0
    veh_a, veh_b = _car(rng), _car(rng)
    vA, vB = rng.uniform(7.0, 13.0), rng.uniform(7.0, 13.0)
    xc = -LANE_Y[-1]
    a = _straight(t, "car", veh_a, vA, [], (xc - vA * T, LANE_Y[-1]), 0.0, role="crossing")

    def mover(delay: float) -> _Mover:
        return _straight(t, "car", veh_b, vB, [], (xc, LANE_Y[-1] - vB * (T + delay)), np.pi / 2,
                         role="passing")

    # the later the second, the larger the clearance once it passes behind
    delay = _solve(lambda d: float(_clearance(a, mover(d)).min()), float(margin_m), 0.0, 3.0)
    b = mover(delay)
    t_min = float(t[int(np.argmin(_clearance(a, b)))])
    scene = _Scene([a, b], [{"kind": "close_pass", "min_ttc": float("nan"), "margin_m":
                             float(_clearance(a, b).min()), "time_of_min": t_min,
                             "movers": [a, b]}])
    return _record(scene, _junction_xodr(), method=method, position_std=position_std,
                   rate_hz=rate_hz, seed=seed, duration_s=16.0,
                   title=f"Two vehicles crossing paths, {margin_m:g} m apart",
                   bounds=(-120.0, -120.0, 120.0, 120.0), return_truth=return_truth,
                   recording_id=f"close-pass-{method}-{seed}")


__all__ = ["CONFLICT_KINDS", "METHODS", "THRESHOLDS", "close_pass_scene", "conflict_scene",
           "design_ttc", "traffic_scene"]
