"""``events`` (origin ``derived``): critical encounters — conflicts and near misses — found with
the evidence the recording's uncertainty gives, hard braking, and the per-recording criticality
summary (docs/derive.md "Events").

1. **Evidence per time step** (:mod:`._episodes`): a pair's time step is critical when the
   probability that its TTC is at most ``ttc_s`` (``derived/interactions``: along the lane in
   closed form from the gap's and the closing speed's Gaussians; 2D from ``evidence_samples``
   Monte Carlo draws of both participants' smoothed states), that its DRAC is at least
   ``drac_mps2`` (where given) or that an encroachment's PET is at most ``pet_s`` is at least
   ``evidence`` (0.9).
2. **Episodes**: consecutive critical steps of a pair (gaps up to ``merge_gap_s``) lasting at
   least ``persistence_s`` (0.3 s of observed time); **encounters**: a pair's episodes of every
   metric closer than ``encounter_gap_s`` are one event, named after its TTC (else PET, else
   DRAC).
3. **Collision probability** (:mod:`._collision`): the share of variations of the recorded
   encounter within the stated uncertainty (positions, velocities, accelerations, heading, size)
   in which the footprints touch within ``collision_horizon_s`` of its most critical moment.
4. **Classification**: ``near_miss`` where that probability is at least ``near_miss_probability``
   (0.5: the paper's "accident averted predominantly due to stochastic effects"), else
   ``conflict`` (critical by the measure, averted by the recorded behaviour).
5. **hard_braking**: episodes of at least ``min_duration_s`` with ``P(a_lon <=
   hard_braking_mps2) >= evidence``.

Thresholds default to ``recording.json:thresholds`` (``ttc_s``, ``pet_s``) and then to 1.5 s. Each
event carries its pair, relation, metric, extreme value ± std and its time, duration, collision
probability ± std in typed columns, and the details (threshold, evidence, the other surrogates,
the other metrics of the encounter, the probability's interval) in ``attributes``;
``confidence`` is the largest probability over the event's steps that the metric was beyond the
threshold. Annotated events are kept; earlier derived events are replaced.
"""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from pydantic import Field

from aveas_format.derive.events._collision import Tracks, collision_probability, one_blas_thread
from aveas_format.derive.events._episodes import (
    braking_episodes,
    encounters,
    join_windows,
    pair_rows,
    pet_episodes,
    threshold_episodes,
    ttc_probability,
)
from aveas_format.derive.registry import DERIVED_KEY, Derivation, Params, register
from aveas_format.io.arrow import column_numpy

VERSION = "2.0.0"
DEFAULT_THRESHOLD_S = 1.5
#: for events named after PET: the variations start this long (s) before the first participant
#: leaves the conflict area
PET_LEAD_S = 1.0


class EventsParams(Params):
    """Parameters of ``events``."""

    ttc_s: float | None = Field(None, gt=0, description="TTC threshold (s); default "
                                "recording.json thresholds.ttc_s, else 1.5")
    pet_s: float | None = Field(None, gt=0, description="PET threshold (s); default "
                                "recording.json thresholds.pet_s, else 1.5")
    hard_braking_mps2: float = Field(-4.0, lt=0, description="a_lon at or below this is hard "
                                     "braking (m/s²)")
    min_duration_s: float = Field(0.2, ge=0, description="shortest hard-braking episode (s)")
    merge_gap_s: float = Field(0.5, ge=0, description="episodes closer than this merge (s)")
    drac_mps2: float | None = Field(None, gt=0, description="DRAC threshold (m/s²) for critical "
                                    "episodes (none: DRAC makes no events of its own)")
    madr_mps2: float = Field(8.45, gt=0, description="mean maximum available deceleration "
                             "(m/s²) of the episodes' CPI")
    madr_std_mps2: float = Field(1.4, ge=0, description="its standard deviation (m/s²)")
    evidence: float = Field(0.9, ge=0.5, le=1.0, description="a time step is critical when the "
                            "probability that its measure is beyond the threshold is at least "
                            "this")
    persistence_s: float = Field(0.3, ge=0, description="shortest critical episode (s of "
                                 "observed time) of TTC and DRAC")
    evidence_samples: int = Field(256, ge=1, description="Monte Carlo draws of a 2D TTC's "
                                  "probability to be below the threshold")
    encounter_gap_s: float = Field(3.0, ge=0, description="a pair's episodes (any metric) "
                                   "closer than this (s) are one event")
    collision_samples: int = Field(400, ge=0, description="Monte Carlo variations of an "
                                   "encounter for its collision probability (0: none)")
    collision_horizon_s: float = Field(4.0, gt=0, description="how long (s) after its most "
                                       "critical moment an encounter's variations are followed")
    driver_accel_std_mps2: float = Field(0.2, ge=0, description="a driver's own variability of "
                                         "the acceleration along the path (m/s²) in the "
                                         "variations")
    driver_accel_length_s: float = Field(1.4, gt=0, description="correlation length (s) of the "
                                         "acceleration variations")
    near_miss_probability: float = Field(0.5, ge=0, le=1, description="an encounter with at "
                                         "least this collision probability is a near_miss, "
                                         "below a conflict")
    seed: int = Field(0, description="random seed of the Monte Carlo draws")


def thresholds(rec, p: EventsParams) -> tuple[float, float]:
    """The TTC and PET thresholds in effect."""
    th = rec.meta.thresholds
    ttc = p.ttc_s or (th.ttc_s if th is not None and th.ttc_s else None) or DEFAULT_THRESHOLD_S
    pet = p.pet_s or (th.pet_s if th is not None and th.pet_s else None) or DEFAULT_THRESHOLD_S
    return float(ttc), float(pet)


def _interaction_params(rec) -> dict:
    """The parameters ``derived/interactions`` was made with (its own metadata, else
    recording.json ``derived``; empty where neither says)."""
    it = rec.derived.get("interactions")
    md = (it.schema.metadata or {}) if it is not None else {}
    if DERIVED_KEY in md:
        try:
            return dict(json.loads(md[DERIVED_KEY]).get("parameters") or {})
        except (ValueError, AttributeError):
            pass
    for e in rec.meta.derived or []:
        if e.table == "derived/interactions":
            return dict(e.parameters or {})
    return {}


class _States:
    """The recording's states as the interactions saw them (smoothed where they chose so), built
    on first use: the 2D TTC draws and the collision probabilities."""

    def __init__(self, rec) -> None:
        self.rec = rec
        self.params = _interaction_params(rec)
        self._S = None
        self._tracks = None

    @property
    def S(self):
        if self._S is None:
            from aveas_format.derive._samples import Samples
            from aveas_format.derive.interactions import smoothed_velocities

            S = Samples(self.rec, float(self.params.get("time_resolution", 1e-6)))
            mode = self.params.get("velocities", "auto")
            if mode != "states":
                smoothed_velocities(S, mode)
            self._S = S
        return self._S

    @property
    def tracks(self) -> Tracks:
        if self._tracks is None:
            self._tracks = Tracks(self.S)
        return self._tracks

    def draws(self, samples: int, seed: int):
        """``(pid, oid, time) -> (samples, rows)`` 2D TTC draws of those pair rows."""
        from aveas_format.derive._samples import find_rows
        from aveas_format.derive.interactions import ttc_draws

        def fn(pid, oid, t):
            S, tr = self.S, self.tracks
            i, ok_i = find_rows(tr.pid, tr.t, pid, t)
            j, ok_j = find_rows(tr.pid, tr.t, oid, t)
            i, j = tr.order[i], tr.order[j]
            d = ttc_draws(S, i, j, samples, seed)[0]
            return np.where((ok_i & ok_j)[None, :], d, np.inf)
        return fn


def _step(rec) -> float:
    """The time one sample stands for (s): the nominal sampling interval."""
    hz = rec.meta.nominal_rate_hz
    return 1.0 / float(hz) if hz else 0.0


def _pair_episodes(rec, ttc_thr: float, pet_thr: float, p: EventsParams, st: _States,
                   open_at: tuple[float, float] | None = None) -> list[dict]:
    """The critical episodes of pairs: TTC, DRAC (where ``drac_mps2`` is given) and PET;
    ``open_at``: of a time window (:func:`window_episodes`)."""
    step = _step(rec)
    eps: list[dict] = []
    it = rec.derived.get("interactions")
    if it is not None and it.num_rows:
        r = pair_rows(it)
        cand = np.flatnonzero(np.isfinite(r["ttc"]) & (r["ttc"] <= ttc_thr))
        prob = np.full(len(r["ttc"]), np.nan)
        if len(cand):
            draws = st.draws(p.evidence_samples, int(st.params.get("seed", 0))) \
                if rec.states is not None and rec.states.num_rows else None
            prob[cand] = ttc_probability(r, cand, ttc_thr, draws)
        eps += threshold_episodes(r, "ttc", ttc_thr, prob, p, step, open_at)
        if p.drac_mps2 is not None:
            d, sd = r["drac"], np.nan_to_num(r["drac_std"])
            from scipy.special import ndtr

            with np.errstate(divide="ignore", invalid="ignore"):
                pd_ = np.where(sd > 0, ndtr((d - p.drac_mps2) / sd),
                               (d >= p.drac_mps2).astype(float))
            pd_ = np.where(np.isfinite(d) & (d >= p.drac_mps2), pd_, np.nan)
            eps += threshold_episodes(r, "drac", p.drac_mps2, pd_, p, step, open_at)
    en = rec.derived.get("encroachments")
    if en is not None and en.num_rows:
        eps += pet_episodes(en, pet_thr, p)
    return eps


def _collision(rec, e: dict, p: EventsParams, st: _States) -> dict | None:
    """The collision probability of the encounter or episode ``e`` (None: not drawn)."""
    if not p.collision_samples or rec.states is None or not rec.states.num_rows:
        return None
    a, b = e["pair"]
    t_ref = e["time_extreme"] if e["metric"] != "pet" else max(
        e["start"] - PET_LEAD_S, max(st.tracks.first_time(a), st.tracks.first_time(b)))
    return collision_probability(st.tracks, a, b, t_ref, p.collision_horizon_s,
                                 p.collision_samples, p.seed, p.driver_accel_std_mps2,
                                 p.driver_accel_length_s)


def _classify(e: dict, p: EventsParams) -> dict:
    """``kind`` of the encounter ``e`` from its ``collision`` probability, which goes into its
    attributes."""
    cp = e["collision"]
    e["kind"] = "near_miss" if cp is not None and cp["p"] >= p.near_miss_probability \
        else "conflict"
    if cp is not None:
        e["attributes"]["collision_probability"] = {
            "p": cp["p"], "std": cp["std"], "ci95": [cp["low"], cp["high"]],
            "t_ref": cp["t_ref"], "horizon_s": cp["horizon"],
            "samples": p.collision_samples, "near_miss_probability": p.near_miss_probability}
    return e


def _pair_events(rec, ttc_thr: float, pet_thr: float, p: EventsParams, st: _States
                 ) -> list[dict]:
    """The encounters (TTC, DRAC, PET episodes merged by pair) with their collision
    probability and kind."""
    out = encounters(_pair_episodes(rec, ttc_thr, pet_thr, p, st), p.encounter_gap_s)
    with one_blas_thread():
        for e in out:
            e["collision"] = _collision(rec, e, p, st)
            _classify(e, p)
    return out


def compute(rec, p: EventsParams) -> pa.Table:
    """The events table: the recording's non-derived events plus freshly derived ones."""
    ttc_thr, pet_thr = thresholds(rec, p)
    st = _States(rec)
    new = _pair_events(rec, ttc_thr, pet_thr, p, st)
    k = rec.derived.get("kinematics")
    if k is not None and k.num_rows:
        for e in braking_episodes(k, p, _step(rec)):
            e["kind"], e["collision"] = "hard_braking", None
            new.append(e)
    return with_kept(new, rec.events)


def window_episodes(rec, p: EventsParams, core: tuple[float, float]) -> list[dict]:
    """The critical episodes of the time window ``core`` = ``[t0, t1)`` of a longer recording
    (derive.streamed): ``rec`` holds the window's interactions, its kinematics from ``t0`` on and
    the states from ``t0`` on (the collision probabilities follow the tracks beyond ``t1``).
    Episodes that may go on in the next or previous window are kept whatever their length
    (``open``). Each episode that can be an encounter's extreme once the windows are joined (the
    extreme of its encounter in the window, or open) carries its ``collision`` probability: it
    is keyed by pair and time, so it is the one deriving at once draws. :func:`from_windows`
    makes the events of all windows."""
    ttc_thr, pet_thr = thresholds(rec, p)
    st = _States(rec)
    eps = _pair_episodes(rec, ttc_thr, pet_thr, p, st, open_at=core)
    main = {id(next(e for e in eps if e["pair"] == m["pair"]
                    and e["time_extreme"] == m["time_extreme"] and e["metric"] == m["metric"]))
            for m in encounters(eps, p.encounter_gap_s)}
    with one_blas_thread():
        for e in eps:
            e["collision"] = _collision(rec, e, p, st) if e["open"] or id(e) in main else None
    k = rec.derived.get("kinematics")
    if k is not None and k.num_rows:
        tk = k.column("time")
        k = k.filter(pc.and_(pc.greater_equal(tk, core[0]), pc.less(tk, core[1])))
        for e in braking_episodes(k, p, _step(rec), open_at=core):
            e["collision"] = None
            eps.append(e)
    return eps


def from_windows(rec, episodes: list[dict], p: EventsParams) -> pa.Table:
    """The events table of ``rec`` (its metadata and events: the non-derived ones are kept) from
    the :func:`window_episodes` of all its windows: the pieces of an episode cut by a window
    boundary joined (:func:`join_windows`), the pairs' episodes merged into encounters and
    classified as :func:`compute` does."""
    eps = join_windows(episodes, p, _step(rec))
    new = encounters([e for e in eps if e["metric"] != "a_lon"], p.encounter_gap_s)
    for e in new:
        _classify(e, p)
    for e in eps:
        if e["metric"] == "a_lon":
            e["kind"] = "hard_braking"
            new.append(e)
    return with_kept(new, rec.events)


def with_kept(new: list[dict], old: pa.Table | None) -> pa.Table:
    """The events table of the derived events ``new`` (dicts with ``kind``) after the
    non-derived events of ``old`` (numbered on from its largest ``event_id``)."""
    for e in new:
        e["attributes"]["method"] = f"derive.events {VERSION}"
    new.sort(key=lambda e: (e["start"], e["pair"]))
    keep = None
    start_id = 0
    if old is not None and old.num_rows:
        origin = old.column("origin")
        origin = origin.cast(pa.string()) if pa.types.is_dictionary(origin.type) else origin
        keep = old.filter(pc.not_equal(origin, "derived"))
        start_id = int(pc.max(old.column("event_id")).as_py()) + 1
    table = events_table(new, start_id)
    if keep is not None and keep.num_rows:
        from aveas_format.io.arrow import conform
        from aveas_format.schema.tables import TABLES

        keep = conform(keep, TABLES["events"])
        table = conform(table, TABLES["events"])
        names = list(dict.fromkeys(keep.column_names + table.column_names))

        def widen(t: pa.Table, like: pa.Table) -> pa.Table:
            for c in names:
                if c not in t.column_names:
                    f = like.schema.field(c)
                    t = t.append_column(f, pa.nulls(t.num_rows, f.type))
            return t.select(names)

        table = pa.concat_tables([widen(keep, table), widen(table, keep)],
                                 promote_options="permissive")
    return table


def _roles(e: dict) -> list[str]:
    if e["kind"] == "hard_braking":
        return ["braking"]
    if e["metric"] == "pet":
        return ["first", "second"]
    return ["follower", "leader"] if e["relation"] == "leader" else ["participant", "other"]


def events_table(new: list[dict], start_id: int = 0) -> pa.Table:
    """Derived events (dicts of :func:`compute`) as rows of the events table."""
    def f64(key, fn=lambda e, k: e[k]):
        v = [fn(e, key) for e in new]
        return pa.array(v, pa.float64())

    def cp(e, k):
        return None if e.get("collision") is None else e["collision"][k]

    return pa.table({
        "event_id": pa.array(np.arange(start_id, start_id + len(new), dtype=np.int64)),
        "kind": pa.array([e["kind"] for e in new], pa.string()),
        "time_start": f64("start"),
        "time_end": f64("end"),
        "participant_ids": pa.array([list(e["pair"]) for e in new], pa.list_(pa.int64())),
        "roles": pa.array([_roles(e) for e in new], pa.list_(pa.string())),
        "confidence": pa.array([round(e["confidence"], 4) for e in new], pa.float32()),
        "origin": pa.array(["derived"] * len(new), pa.string()),
        "attributes": pa.array([json.dumps(e["attributes"]) for e in new], pa.string()),
        "metric": pa.array([e["metric"] for e in new], pa.string()),
        "relation": pa.array([e["relation"] for e in new], pa.string()),
        "value": f64("value"),
        "value_std": f64("std"),
        "time_extreme": f64("time_extreme"),
        "duration": f64("duration"),
        "collision_probability": f64("p", cp),
        "collision_probability_std": f64("std", cp),
    })


#: units of the metrics of derived events
METRIC_UNITS = {"ttc": "s", "pet": "s", "drac": "m/s²", "a_lon": "m/s²"}
#: one line each for the tables that list events (info, find, the HTML report)
EXPLAIN = {
    "kind": "conflict: critical by its measure and averted by the behaviour the recording shows; "
            "near_miss: averted predominantly by chance (P(collision) at least 0.5)",
    "value": "the event's extreme (TTC, PET: smallest; DRAC: largest) ± 1 std",
    "P(collision)": "the share of variations of the recorded encounter — its state within the "
                    "stated uncertainty, a driver's variability of the acceleration — in which the "
                    "two touch (± its Monte Carlo std)",
    "CPI": "crash potential index: the share of the observed time in which the deceleration "
           "needed to avoid a crash (DRAC) exceeds the one available, N(8.45, 1.4²) m/s² on dry "
           "asphalt",
    "TET / TIT": "time exposed / time integrated TTC: the time (s) with TTC at or below the "
                 "threshold, and the integral of threshold - TTC over it (s²), summed over "
                 "participants",
}


def worst_events(events: pa.Table | None, top: int | None = None) -> list[dict]:
    """The derived conflicts and near misses of ``events``, most critical first (the largest
    collision probability, then the smallest TTC or PET, then the largest DRAC), as dicts with
    ``event_id``, ``kind``, ``participant_ids``, ``relation``, ``time_start``, ``time_end``,
    ``time_extreme``, ``metric``, ``value``, ``value_std``, ``duration``,
    ``collision_probability`` and ``collision_probability_std`` (None where the events table
    predates these columns)."""
    if events is None or not events.num_rows:
        return []
    cols = ("event_id", "kind", "origin", "participant_ids", "relation", "time_start", "time_end",
            "time_extreme", "metric", "value", "value_std", "duration", "collision_probability",
            "collision_probability_std", "attributes")
    d = events.select([c for c in cols if c in events.column_names]).to_pylist()
    out = []
    for r in d:
        if str(r.get("origin")) != "derived" or str(r.get("kind")) not in ("near_miss",
                                                                              "conflict"):
            continue
        row = {c: r.get(c) for c in cols if c not in ("origin", "attributes")}
        row["kind"] = str(row["kind"])
        if row.get("metric") is None and r.get("attributes"):  # written before the columns
            a = json.loads(r["attributes"]) or {}
            row["metric"] = a.get("metric")
            row["value"] = a.get("min_value_s", a.get("value_s", a.get("max_value_mps2")))
            row["value_std"] = a.get("min_value_std_s", a.get("value_std_s"))
            row["relation"] = a.get("relation")
        out.append(row)

    def key(r):
        p = r.get("collision_probability")
        v = r.get("value")
        v = float("inf") if v is None else (-v if r.get("metric") == "drac" else v)
        return (-(p if p is not None else 0.0), r.get("metric") == "drac", v)

    out.sort(key=key)
    return out[:top] if top is not None else out


def format_value(metric: str | None, value, std, digits: int = 2) -> str:
    """``0.92 ± 0.07 s`` (the metric's unit; ``-`` without a value)."""
    if value is None:
        return "-"
    unit = METRIC_UNITS.get(metric or "", "")
    sd = f" ± {std:.{digits}f}" if std is not None else ""
    return f"{value:.{digits}f}{sd}{(' ' + unit) if unit else ''}"


def format_probability(p, std) -> str:
    """``0.16 ± 0.02`` (``-`` without a value; ``< 0.01`` where the draws never touched)."""
    if p is None:
        return "-"
    if p == 0.0:
        return "< 0.01" if std is not None and std < 0.01 else "0"
    return f"{p:.2f}" + (f" ± {std:.2f}" if std is not None else "")


def _min_row(table: pa.Table, col: str) -> dict | None:
    """The row of ``table`` with the smallest finite ``col`` (None: it has none)."""
    v = column_numpy(table, col, missing=np.nan)
    if not np.isfinite(v).any():
        return None
    return table.slice(int(np.nanargmin(np.where(np.isfinite(v), v, np.nan))), 1).to_pylist()[0]


def criticality_summary(rec) -> dict:
    """Per-recording criticality facts for ``aveas-format info``: minimum TTC (with the pair, time
    and kind), minimum PET, counts of derived near misses (by metric) and hard-braking events, the
    thresholds and, where ``derived/criticality_summary`` exists, its recording row (TET, TIT, CPI,
    max DRAC, min PSD with their std, samples below the TTC threshold, the worst events). Uses
    what the recording's derived tables and events hold; empty values where a table is missing.
    ``worst``: the five most critical derived events (:func:`worst_events`)."""
    out: dict = {"min_ttc_s": None, "min_pet_s": None, "near_misses": 0, "near_misses_ttc": 0,
                 "near_misses_pet": 0, "near_misses_drac": 0, "conflicts": 0, "hard_braking": 0}
    th = rec.meta.thresholds
    out["thresholds"] = th.model_dump(exclude_none=True) if th is not None else {}
    it = rec.derived.get("interactions")
    if it is not None and it.num_rows:
        row = _min_row(it, "ttc")
        if row is not None:
            out["min_ttc_s"] = {"value": row["ttc"], "std": row.get("ttc_std"),
                                "participant_id": row["participant_id"],
                                "other_id": row["other_id"], "time": row["time"],
                                "relation": str(row["relation"]), "kind": row.get("ttc_kind")}
    en = rec.derived.get("encroachments")
    if en is not None and en.num_rows:
        row = _min_row(en, "pet")
        if row is not None:
            out["min_pet_s"] = {"value": row["pet"], "std": row.get("pet_std"),
                                "first_id": row["first_id"], "second_id": row["second_id"],
                                "time": row["time_first_exit"]}
        out["encroachments"] = en.num_rows
    cs = rec.derived.get("criticality_summary")
    if cs is not None and cs.num_rows:
        rows = [r for r in cs.to_pylist() if str(r["scope"]) == "recording"]
        if rows:
            r = rows[0]
            for k in ("tet", "tit", "cpi", "max_drac", "min_psd"):
                out[k] = None if r.get(k) is None else {"value": r[k], "std": r.get(f"{k}_std")}
            out["ttc_samples_below"] = r.get("ttc_samples_below")
            out["worst_events"] = r.get("worst_events") or []
    ev = rec.events
    if ev is not None and ev.num_rows:
        d = ev.to_pydict()
        for kind, origin, attr in zip(d["kind"], d["origin"], d.get("attributes") or
                                      [None] * ev.num_rows):
            if str(origin) != "derived":
                continue
            if str(kind) == "near_miss":
                out["near_misses"] += 1
                metric = (json.loads(attr) or {}).get("metric") if attr else None
                if metric in ("ttc", "pet", "drac"):
                    out[f"near_misses_{metric}"] += 1
            elif str(kind) == "conflict":
                out["conflicts"] += 1
            elif str(kind) == "hard_braking":
                out["hard_braking"] += 1
        out["worst"] = worst_events(ev, 5)
    return out


EVENTS = register(Derivation(
    name="events",
    table="events",
    version=VERSION,
    params=EventsParams,
    fn=compute,
    needs={},
    optional=("states", "participants", "derived/interactions", "derived/encroachments",
              "derived/kinematics"),
    after=("kinematics", "interactions", "encroachments"),
    doc="conflicts and near misses (TTC, PET, DRAC with the evidence of their uncertainty, "
        "classified by their collision probability) and hard braking",
    method=lambda p: "evidence+collision_probability",
))
