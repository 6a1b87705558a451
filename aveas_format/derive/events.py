"""``events`` (origin ``derived``): near misses and hard braking from thresholds, and the
per-recording criticality summary.

- **near_miss (TTC)**: consecutive time steps (gaps up to ``merge_gap_s``) at which a pair's TTC in
  ``derived/interactions`` is at most ``ttc_s``; one event per pair and episode. Leader rows and
  conflicting rows are used (follower rows repeat them).
- **near_miss (PET)**: rows of ``derived/encroachments`` with ``pet <= pet_s``; the event spans
  ``time_first_exit .. time_second_enter``.
- **hard_braking**: episodes of at least ``min_duration_s`` with ``a_lon <= hard_braking_mps2`` in
  ``derived/kinematics``.

Thresholds default to ``recording.json:thresholds`` (``ttc_s``, ``pet_s``) and then to 1.5 s. Each
event's ``attributes`` JSON records the metric, the threshold, the extreme value with its standard
deviation and the method; ``confidence`` is the probability that the metric was below the
threshold at its extreme, ``Φ((threshold - value)/std)`` (1 where no std is known). Annotated
events are kept; earlier derived events are replaced.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from pydantic import Field

from aveas_format.derive._samples import ragged, segments, string_values
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.io.arrow import column_numpy

VERSION = "1.0.0"
DEFAULT_THRESHOLD_S = 1.5


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


def thresholds(rec, p: EventsParams) -> tuple[float, float]:
    """The TTC and PET thresholds in effect."""
    th = rec.meta.thresholds
    ttc = p.ttc_s or (th.ttc_s if th is not None and th.ttc_s else None) or DEFAULT_THRESHOLD_S
    pet = p.pet_s or (th.pet_s if th is not None and th.pet_s else None) or DEFAULT_THRESHOLD_S
    return float(ttc), float(pet)


def _phi(z: float) -> float:
    return 0.5 * (1.0 + math.erf(z / math.sqrt(2.0)))


def _confidence(threshold: float, value: float, std: float | None, below: bool = True) -> float:
    if std is None or not np.isfinite(std) or std <= 0:
        return 1.0
    z = (threshold - value) / std if below else (value - threshold) / std
    return round(_phi(z), 4)


def _episodes(key: np.ndarray, t: np.ndarray, gap: float) -> np.ndarray:
    """Episode id per row (rows sorted by key, time): a new episode at a new key or time gap."""
    return ragged(segments(key, t, gap)[1])[0]


def _ttc_events(rec, ttc_thr: float, p: EventsParams) -> list[dict]:
    it = rec.derived.get("interactions")
    if it is None or it.num_rows == 0:
        return []
    rel = string_values(it, "relation")
    pid = it.column("participant_id").to_numpy()
    oid = it.column("other_id").to_numpy()
    t, ttc, std = (column_numpy(it, c, missing=np.nan) for c in ("time", "ttc", "ttc_std"))
    kind = string_values(it, "ttc_kind")
    use = ((rel == "leader") | ((rel == "conflicting") & (pid < oid))
           | (np.isin(rel, ["left_neighbour", "right_neighbour"]) & (pid < oid)))
    m = use & np.isfinite(ttc) & (ttc <= ttc_thr)
    if not m.any():
        return []
    a, b = pid[m], oid[m]
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    key = lo * (int(hi.max()) + 1) + hi
    o = np.lexsort((t[m], key))
    ep = _episodes(key[o], t[m][o], p.merge_gap_s)
    out = []
    rows = np.flatnonzero(m)[o]
    for e in np.unique(ep):
        r = rows[ep == e]
        k = r[np.argmin(ttc[r])]
        roles = (["follower", "leader"] if rel[k] == "leader" else ["participant", "other"])
        sd = float(std[k]) if np.isfinite(std[k]) else None
        out.append({
            "kind": "near_miss", "time_start": float(t[r].min()), "time_end": float(t[r].max()),
            "participant_ids": [int(pid[k]), int(oid[k])], "roles": roles,
            "confidence": _confidence(ttc_thr, float(ttc[k]), sd),
            "attributes": {"metric": "ttc", "ttc_kind": kind[k], "relation": rel[k],
                           "threshold_s": ttc_thr, "min_value_s": float(ttc[k]),
                           "min_value_std_s": sd, "time_of_min": float(t[k]),
                           "method": f"derive.events {VERSION}"},
        })
    return out


def _pet_events(rec, pet_thr: float) -> list[dict]:
    en = rec.derived.get("encroachments")
    if en is None or en.num_rows == 0:
        return []
    pet, std, t0, t1 = (column_numpy(en, c, missing=np.nan) for c in
                        ("pet", "pet_std", "time_first_exit", "time_second_enter"))
    first = en.column("first_id").to_numpy()
    second = en.column("second_id").to_numpy()
    cid = en.column("conflict_id").to_numpy()
    out = []
    for k in np.flatnonzero(np.isfinite(pet) & (pet <= pet_thr)):
        sd = float(std[k]) if np.isfinite(std[k]) else None
        out.append({
            "kind": "near_miss", "time_start": float(min(t0[k], t1[k])),
            "time_end": float(max(t0[k], t1[k])),
            "participant_ids": [int(first[k]), int(second[k])], "roles": ["first", "second"],
            "confidence": _confidence(pet_thr, float(pet[k]), sd),
            "attributes": {"metric": "pet", "threshold_s": pet_thr, "value_s": float(pet[k]),
                           "value_std_s": sd, "conflict_id": int(cid[k]),
                           "method": f"derive.events {VERSION}"},
        })
    return out


def _braking_events(rec, p: EventsParams) -> list[dict]:
    k = rec.derived.get("kinematics")
    if k is None or k.num_rows == 0:
        return []
    pid = k.column("participant_id").to_numpy()
    t, a, sd = (column_numpy(k, c, missing=np.nan) for c in ("time", "a_lon", "a_lon_std"))
    m = np.isfinite(a) & (a <= p.hard_braking_mps2)
    if not m.any():
        return []
    rows = np.flatnonzero(m)
    ep = _episodes(pid[rows], t[rows], p.merge_gap_s)
    out = []
    for e in np.unique(ep):
        r = rows[ep == e]
        if t[r].max() - t[r].min() < p.min_duration_s:
            continue
        j = r[np.argmin(a[r])]
        s = float(sd[j]) if np.isfinite(sd[j]) else None
        out.append({
            "kind": "hard_braking", "time_start": float(t[r].min()), "time_end": float(t[r].max()),
            "participant_ids": [int(pid[j])], "roles": ["braking"],
            "confidence": _confidence(p.hard_braking_mps2, float(a[j]), s),
            "attributes": {"metric": "a_lon", "threshold_mps2": p.hard_braking_mps2,
                           "min_value_mps2": float(a[j]), "min_value_std_mps2": s,
                           "time_of_min": float(t[j]), "method": f"derive.events {VERSION}"},
        })
    return out


def compute(rec, p: EventsParams) -> pa.Table:
    """The events table: the recording's non-derived events plus freshly derived ones."""
    ttc_thr, pet_thr = thresholds(rec, p)
    new = _ttc_events(rec, ttc_thr, p) + _pet_events(rec, pet_thr) + _braking_events(rec, p)
    old = rec.events
    keep = None
    start_id = 0
    if old is not None and old.num_rows:
        origin = old.column("origin")
        origin = origin.cast(pa.string()) if pa.types.is_dictionary(origin.type) else origin
        keep = old.filter(pc.not_equal(origin, "derived"))
        start_id = int(pc.max(old.column("event_id")).as_py()) + 1
    table = pa.table({
        "event_id": pa.array(np.arange(start_id, start_id + len(new), dtype=np.int64)),
        "kind": pa.array([e["kind"] for e in new], pa.string()),
        "time_start": pa.array([e["time_start"] for e in new], pa.float64()),
        "time_end": pa.array([e["time_end"] for e in new], pa.float64()),
        "participant_ids": pa.array([e["participant_ids"] for e in new], pa.list_(pa.int64())),
        "roles": pa.array([e["roles"] for e in new], pa.list_(pa.string())),
        "confidence": pa.array([e["confidence"] for e in new], pa.float32()),
        "origin": pa.array(["derived"] * len(new), pa.string()),
        "attributes": pa.array([json.dumps(e["attributes"]) for e in new], pa.string()),
    })
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


def criticality_summary(rec) -> dict:
    """Per-recording criticality facts for ``aveas-format info``: minimum TTC (with the pair, time
    and kind), minimum PET, counts of derived near misses (by metric) and hard-braking events, and
    the thresholds. Uses what the recording's derived tables and events hold; empty values where a
    table is missing."""
    out: dict = {"min_ttc_s": None, "min_pet_s": None, "near_misses": 0, "near_misses_ttc": 0,
                 "near_misses_pet": 0, "hard_braking": 0}
    th = rec.meta.thresholds
    out["thresholds"] = th.model_dump(exclude_none=True) if th is not None else {}
    it = rec.derived.get("interactions")
    if it is not None and it.num_rows:
        ttc = column_numpy(it, "ttc", missing=np.nan)
        if np.isfinite(ttc).any():
            k = int(np.nanargmin(np.where(np.isfinite(ttc), ttc, np.nan)))
            row = it.slice(k, 1).to_pylist()[0]
            out["min_ttc_s"] = {"value": row["ttc"], "std": row.get("ttc_std"),
                                "participant_id": row["participant_id"],
                                "other_id": row["other_id"], "time": row["time"],
                                "relation": str(row["relation"]), "kind": row.get("ttc_kind")}
    en = rec.derived.get("encroachments")
    if en is not None and en.num_rows:
        pet = column_numpy(en, "pet", missing=np.nan)
        if np.isfinite(pet).any():
            k = int(np.nanargmin(np.where(np.isfinite(pet), pet, np.nan)))
            row = en.slice(k, 1).to_pylist()[0]
            out["min_pet_s"] = {"value": row["pet"], "std": row.get("pet_std"),
                                "first_id": row["first_id"], "second_id": row["second_id"],
                                "time": row["time_first_exit"]}
        out["encroachments"] = en.num_rows
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
                if metric in ("ttc", "pet"):
                    out[f"near_misses_{metric}"] += 1
            elif str(kind) == "hard_braking":
                out["hard_braking"] += 1
    return out


EVENTS = register(Derivation(
    name="events",
    table="events",
    version=VERSION,
    params=EventsParams,
    fn=compute,
    needs={},
    optional=("derived/interactions", "derived/encroachments", "derived/kinematics"),
    after=("kinematics", "interactions", "encroachments"),
    doc="near-miss (TTC, PET) and hard-braking events from thresholds",
    method=lambda p: "thresholds",
))
