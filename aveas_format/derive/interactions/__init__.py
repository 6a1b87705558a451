"""``derived/interactions``: lane leaders/followers, neighbours and conflicting pairs with TTC,
gap, THW, DHW and closing speed, each per time step.

Lane relations come from the road coordinates (``road_id``, ``lane_id``, ``road_s``). Lanes are
chained along the direction of travel across lane sections and roads wherever the map's links give
a unique continuation (:func:`lane_graph`); each sample gets a *chain* and a travel coordinate
``u`` along it, and one sort by ``(time, chain, u)`` gives every leader within a chain. The
frontmost sample of a chain at a time step looks on beyond the chain's end along its *route*
(diverges, junction entries, merges): where the chain has several continuations, the one the
participant itself occupies later in the recording (by lane, else by road); where its later
samples show none (the recording ends first, or it leaves the lane sideways), all of them,
nearest vehicle first; up to ``route_range`` beyond the chain's end. Followers mirror leaders, so a vehicle just past a merge
has one follower per approaching lane. Left and right neighbours are the lead (front level with or
ahead of the participant's front) and the lag (front behind it) in the adjacent lanes, found along
the adjacent lane's chain within ``neighbour_range``.

Conventions (docs/derive.md):

- ``gap``: net bumper-to-bumper clearance along the lane, ``u_leader - u_follower - (L_l + L_f)/2``
  (centre reference points, lengths from ``participants``); negative where the footprints overlap
  longitudinally (side by side for neighbours).
- ``thw``: net time headway ``gap / v_follower`` (null where the follower does not move forward);
  ``dhw``: gross distance headway front-to-front, ``gap + L_leader``. In a ``leader`` row the
  headways are the participant's own, in a ``follower`` row those of the follower behind it.
- ``dhw`` of a neighbour row: the signed front-to-front distance along the lanes, the
  neighbour's front minus the participant's (>= 0: lead, < 0: lag).
- ``closing_speed``: ``v_follower - v_leader`` along the lane for lane pairs, the range rate
  ``-d|Δp|/dt`` for neighbours and conflicting pairs (positive = approaching).
- ``ttc`` (``lane_1d``): ``gap / closing_speed`` when closing, with ``ttc_std`` by the delta method
  from the position, velocity and length uncertainties; null when not closing. Extra columns
  ``ttc_ca``/``ttc_ca_std``: the constant-acceleration variant (vehicles do not reverse), with
  accelerations from ``derived/kinematics``.
- ``ttc`` (``box_2d``): first contact time of the two oriented rectangles under constant velocity
  (exact, separating axes on the relative motion), for pairs found within ``search_radius`` on a
  vectorised spatial grid per time step that are not lane leader/follower; ``ttc_std`` from Monte
  Carlo samples of positions, velocities, headings and sizes. ``conflicting`` rows are those pairs
  with a finite 2D TTC up to ``horizon`` that are not neighbours.

Modules (``aveas_format.derive.interactions``): this one holds the parameters, :func:`compute`,
the table and the registration; private modules hold the rest: ``_pairs`` the lane relations
(leaders and followers along chains and routes, neighbours); ``_lanes`` the lane chains of the map
and each sample's place on them; ``_ttc`` the 1D TTC (constant velocity and acceleration), THW and
DHW with their std; ``_boxes`` the 2D TTC of oriented boxes, the candidate-pair grid and the
conflicting rows; ``_velocities`` the choice of velocities and the projections on a direction. The
states rows as arrays come from :mod:`aveas_format.derive._samples`.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from pydantic import Field

from aveas_format.derive._samples import Samples
from aveas_format.derive.interactions._boxes import (
    box_conflicts,
    candidate_pairs,
    ttc_boxes,
    ttc_draws,
)
from aveas_format.derive.interactions._lanes import LaneGraph, lane_chains, lane_graph
from aveas_format.derive.interactions._pairs import KIND_NAMES, REL_NAMES, SURROGATE_KEYS, lane_rows
from aveas_format.derive.interactions._ttc import ttc_constant_acceleration, ttc_constant_velocity
from aveas_format.derive.interactions._velocities import smoothed_velocities
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.schema.columns import MAY, MUST, col, enum_col, gaussian, pid_col, time_col
from aveas_format.schema.enums import Relation, TtcKind
from aveas_format.schema.tables import derived_table


class InteractionsParams(Params):
    """Parameters of ``interactions``."""

    neighbour_range: float = Field(100.0, gt=0, description="largest distance (m) along the "
                                   "lanes between the fronts of a participant and its left/right "
                                   "lead or lag")
    search_radius: float | None = Field(None, gt=0, description="largest centre distance (m) "
                                        "of a candidate pair for a 2D conflict; default: none, "
                                        "the pairs that can touch within `horizon` at their "
                                        "relative speed are searched, however far apart")
    horizon: float = Field(10.0, gt=0, description="largest 2D TTC (s) reported for conflicting "
                           "pairs")
    samples: int = Field(32, ge=0, description="Monte Carlo samples for the 2D ttc_std (0: none)")
    seed: int = Field(0, description="random seed of the Monte Carlo samples")
    time_resolution: float = Field(1e-6, gt=0, description="times closer than this (s) are one "
                                   "time step")
    box_2d: bool = Field(True, description="compute 2D TTC for non-lane pairs")
    max_heading_deviation: float = Field(1.0, gt=0, description="samples whose heading deviates "
                                         "more than this (rad) from their lane's direction of "
                                         "travel take part in 2D conflicts only")
    route_range: float = Field(250.0, gt=0, description="how far (m) beyond the end of its lane "
                               "chain a leader is searched along the participant's route (across "
                               "diverges, merges and junctions)")
    reaction_time: float = Field(1.0, ge=0, description="perception-reaction time (s) of MDRAC "
                                 "(SUMO's device.ssm.mdrac.prt)")
    max_deceleration: float = Field(3.4, gt=0, description="deceleration (m/s²) of the minimum "
                                    "stopping distance in PSD")
    velocities: Literal["auto", "states", "smoothed"] = Field(
        "auto", description="velocity along the direction of motion: the states' (measured) or "
        "derived/kinematics' smoothed speed; auto: the one with the smaller std per sample")


def compute(rec, p: InteractionsParams, core: tuple[float, float] | None = None) -> pa.Table:
    """The ``derived/interactions`` table of ``rec``; ``core`` ``(t0, t1)``: only the rows of the
    time steps in ``[t0, t1)`` (a time window, derive.streamed), the states of the other times
    only telling the participants' routes (a time step's rows need that step's states only, and
    the later lanes of its participants)."""
    S = Samples(rec, p.time_resolution)
    active = None if core is None else (S.t >= core[0]) & (S.t < core[1])
    if p.velocities != "states":
        smoothed_velocities(S, p.velocities)
    lane = lane_rows(rec, S, p, active)
    parts = []
    if lane:
        parts.append(lane)
    if p.box_2d:
        # also gives the neighbour rows their 2D TTC
        conflicting = box_conflicts(S, lane, p, active)
        if conflicting:
            parts.append(conflicting)
    if not parts:
        return _table(S, {k: np.zeros(0, t) for k, t in
                          (("i", np.int64), ("j", np.int64), ("rel", np.int8), ("gap", float),
                           ("gap_var", float), ("closing", float), ("closing_var", float),
                           ("ttc", float),
                           ("ttc_std", float), ("thw", float), ("dhw", float), ("ttc_ca", float),
                           ("ttc_ca_std", float), ("kind", np.int8),
                           *((k, float) for k in SURROGATE_KEYS))})
    allr = {k: np.concatenate([q[k] for q in parts]) for k in parts[0]}
    return _table(S, allr)


def _f(v: np.ndarray) -> pa.Array:
    """float64 array with nulls for NaN and +inf (null = undefined / no collision course)."""
    v = np.asarray(v, float)
    return pa.array(v, pa.float64(), mask=~np.isfinite(v))


_NAMES_REL, _NAMES_KIND = pa.array(REL_NAMES, pa.string()), pa.array(KIND_NAMES, pa.string())


def _row_order(S: Samples, i: np.ndarray, j: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """The order of the rows ``(i, j, rel)`` by participant, time, other participant and ``rel``
    (small codes): ``np.lexsort((rel, S.pid[j], S.t[i], S.pid[i]))`` as one stable sort of an
    integer key of their ranks (3x faster for a window's rows; times by time step); lexsort
    where the key would not fit in 62 bits."""
    ids, rank = np.unique(S.pid, return_inverse=True)
    rank = rank.ravel()
    n_step = int(S.tstep.max()) + 1 if S.n else 1
    n_rel = int(rel.max()) + 1 if len(rel) else 1
    if len(ids) ** 2 * n_step * n_rel >= 1 << 62:
        return np.lexsort((rel, S.pid[j], S.t[i], S.pid[i]))
    key = ((rank[i] * n_step + S.tstep[i]) * len(ids) + rank[j]) * n_rel + rel
    return np.argsort(key, kind="stable")


def _table(S: Samples, r: dict[str, np.ndarray]) -> pa.Table:
    i, j = r["i"].astype(np.int64), r["j"].astype(np.int64)
    rel, kind = r["rel"], r["kind"]
    if len(i):
        # the table's order (participant, time, other, relation), sorted on the index arrays
        order = _row_order(S, i, j, rel)
        r = {k: v[order] for k, v in r.items() if k not in ("i", "j")}
        i, j, rel, kind = i[order], j[order], r["rel"], r["kind"]
    # the string columns from their codes at once (object arrays compare and gather slowly)
    kind = pc.if_else(pa.array(np.isfinite(r["ttc"])), _NAMES_KIND.take(pa.array(kind)),
                      pa.scalar(None, pa.string()))
    rel = _NAMES_REL.take(pa.array(rel))
    ttc = r["ttc"]
    t = pa.table({
        "participant_id": pa.array(S.pid[i], pa.int64()),
        "time": pa.array(S.t[i], pa.float64()),
        "other_id": pa.array(S.pid[j], pa.int64()),
        "relation": rel,
        "ttc": _f(ttc),
        "ttc_std": _f(np.where(np.isfinite(ttc), r["ttc_std"], np.nan)),
        "ttc_kind": kind,
        "gap": _f(r["gap"]),
        "gap_std": _f(np.sqrt(r["gap_var"])),
        "thw": _f(r["thw"]),
        "dhw": _f(r["dhw"]),
        "closing_speed": _f(r["closing"]),
        "closing_speed_std": _f(np.sqrt(r["closing_var"])),
        "ttc_ca": _f(r["ttc_ca"]),
        "ttc_ca_std": _f(np.where(np.isfinite(r["ttc_ca"]), r["ttc_ca_std"], np.nan)),
        **{k: _f(r[k]) for k in SURROGATE_KEYS},
    })
    return t


TABLE = derived_table(
    "interactions",
    doc="Pairwise relations per time step: leaders, followers, neighbours and conflicting "
    "participants with time to collision and headways.",
    key=("participant_id", "time", "other_id", "relation"),
    sort=("participant_id", "time", "other_id"),
    columns=(
        pid_col(),
        time_col(),
        col("other_id", "int64", MUST, "the other participant", minimum=0, nullable=False),
        enum_col("relation", Relation.values(), MUST, "relation of `other_id` to `participant_id`",
                 nullable=False),
        *gaussian("ttc", "s", MAY, "time to collision (null = no collision course)", minimum=0.0),
        enum_col("ttc_kind", TtcKind.values(), MAY, "how `ttc` was computed"),
        *gaussian("ttc_ca", "s", MAY, "time to collision with constant accelerations (vehicles stop "
                  "rather than reverse; null = no collision)", minimum=0.0),
        *gaussian("gap", "m", MAY, "net bumper-to-bumper gap"),
        col("thw", "float64", MAY, "time headway: net gap / speed of the follower (null = infinite)",
            "s", minimum=0.0),
        col("dhw", "float64", MAY, "distance headway: gross front-to-front spacing (gap + leader "
            "length); in left/right_neighbour rows the signed front-to-front distance along the "
            "lane (>= 0: the neighbour leads, < 0: it lags)", "m"),
        *gaussian("closing_speed", "m/s", MAY, "rate at which the gap closes (positive = "
                  "closing)"),
        *gaussian("drac", "m/s²", MAY, "deceleration rate to avoid a crash: closing speed² / (2 "
                  "gap) for lane pairs, |relative velocity| / (2 TTC) for 2D pairs (null = not "
                  "closing)", minimum=0.0),
        *gaussian("mdrac", "m/s²", MAY, "DRAC after the reaction time `reaction_time`: closing "
                  "speed / (2 (TTC - reaction time)) (null where TTC <= reaction time or not "
                  "closing)", minimum=0.0),
        *gaussian("psd", None, MAY, "proportion of stopping distance: distance to the potential "
                  "collision point / minimum stopping distance at `max_deceleration` (< 1: "
                  "cannot stop before it)", minimum=0.0),
    ),
)

INTERACTIONS = register(Derivation(
    name="interactions",
    spec=TABLE,
    version="1.4.0",
    params=InteractionsParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "x", "y", "heading", "vx", "vy"),
           "participants": ("participant_id", "length", "width")},
    optional=("derived/kinematics",),
    after=("kinematics",),
    doc="lane leaders/followers and neighbours with gap, THW, DHW, closing speed and 1D TTC "
        "(constant velocity and constant acceleration); 2D TTC of oriented boxes for conflicting "
        "pairs; DRAC, MDRAC and PSD of every pair with a TTC",
    method=lambda p: "lane_1d+box_2d" if p.box_2d else "lane_1d",
))

__all__ = ["INTERACTIONS", "TABLE", "InteractionsParams", "LaneGraph", "candidate_pairs", "compute",
           "lane_chains", "lane_graph", "smoothed_velocities", "ttc_boxes",
           "ttc_constant_acceleration", "ttc_constant_velocity", "ttc_draws"]
