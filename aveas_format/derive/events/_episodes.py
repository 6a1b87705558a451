"""Critical episodes from the surrogate measures with the evidence their uncertainty gives.

A time step of a pair is *critical* when the probability that its measure is beyond the
threshold is at least ``evidence`` (:func:`ttc_probability`: TTC along the lane in closed form
from the gap's and the closing speed's Gaussians, the 2D box TTC from Monte Carlo draws of both
participants' states; DRAC, PET and ``a_lon`` from their normal approximations). Consecutive
critical steps of one pair (gaps up to ``merge_gap_s``) form an *episode*, kept when it lasts at
least ``persistence_s`` (its observed time, in seconds, so the rule does not depend on the
sampling rate); :func:`encounters` merges a pair's episodes of every metric that are closer
than ``encounter_gap_s`` into one encounter. The measures, definitions and the numbers that chose
the defaults: docs/derive.md "Events".
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import pyarrow as pa
from scipy.special import ndtr

from aveas_format.derive._samples import ragged, segments, string_values
from aveas_format.io.arrow import column_numpy

if TYPE_CHECKING:
    from aveas_format.derive.events import EventsParams

#: the columns of ``derived/interactions`` an episode reads
PAIR_COLUMNS = ("time", "ttc", "ttc_std", "gap", "gap_std", "closing_speed", "closing_speed_std",
                "drac", "drac_std", "mdrac", "mdrac_std", "psd", "psd_std")
#: the metric an encounter is named after, first the one present
METRIC_ORDER = ("ttc", "pet", "drac")


def _num(v) -> float | None:
    return float(v) if v is not None and np.isfinite(v) else None


def pair_rows(it: pa.Table) -> dict[str, np.ndarray]:
    """The rows of derived/interactions that describe a pair once (leader rows; conflicting and
    neighbour rows with participant_id < other_id) as arrays."""
    rel = string_values(it, "relation")
    pid = it.column("participant_id").to_numpy()
    oid = it.column("other_id").to_numpy()
    use = ((rel == "leader") | ((rel == "conflicting") & (pid < oid))
           | (((rel == "left_neighbour") | (rel == "right_neighbour")) & (pid < oid)))
    r = {"rel": rel[use], "pid": pid[use], "oid": oid[use],
         "kind": string_values(it, "ttc_kind")[use]}
    for c in PAIR_COLUMNS:
        r[c] = (column_numpy(it, c, missing=np.nan)[use] if c in it.column_names
                else np.full(int(use.sum()), np.nan))
    return r


def ttc_probability(r: dict[str, np.ndarray], rows: np.ndarray, thr: float,
                    draws: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None
                    ) -> np.ndarray:
    """``P(TTC <= thr)`` of the pair rows ``rows``.

    Along the lane (``lane_1d``): TTC ``<= thr`` exactly when ``gap - thr * closing <= 0``, a
    normal variable for Gaussian gap and closing speed: ``Φ((thr Δv - g) / sqrt(σ_g² + thr²
    σ_Δv²))`` (a std that is not known counts as 0). 2D (``box_2d``): the share of the Monte Carlo
    draws ``draws(pid, oid, time) -> (samples, rows)`` that touch within ``thr``; without draws
    (no states to draw from), 1 where the point value is below ``thr``."""
    out = np.full(len(rows), np.nan)
    if not len(rows):
        return out
    kind = r["kind"][rows]
    one = kind == "lane_1d"
    if one.any():
        k = rows[one]
        g, dv = r["gap"][k], r["closing_speed"][k]
        s = np.sqrt(np.nan_to_num(r["gap_std"][k]) ** 2
                    + thr ** 2 * np.nan_to_num(r["closing_speed_std"][k]) ** 2)
        z = thr * dv - g
        with np.errstate(divide="ignore", invalid="ignore"):
            p = np.where(s > 0, ndtr(z / s), (z >= 0).astype(float))
        # rows without a gap (a TTC from elsewhere) fall back to their point value
        out[one] = np.where(np.isfinite(g) & np.isfinite(dv), p, 1.0)
    two = ~one
    if two.any():
        k = rows[two]
        if draws is None:
            out[two] = 1.0
        else:
            d = draws(r["pid"][k], r["oid"][k], r["time"][k])
            out[two] = (d <= thr).mean(axis=0)
    return out


def _episode_ids(key: np.ndarray, t: np.ndarray, gap: float) -> np.ndarray:
    """Episode id per row (rows sorted by key, time): a new episode at a new key or time gap."""
    return ragged(segments(key, t, gap)[1])[0]


def pair_key(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One integer per unordered pair (not ``lo * (max + 1) + hi``, which overflows int64 for ids
    above 2**32)."""
    if not len(a):
        return np.zeros(0, np.int64)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.unique(np.column_stack([lo, hi]), axis=0, return_inverse=True)[1].ravel()


def _surrogates_of(r: dict[str, np.ndarray], rows: np.ndarray, p: EventsParams) -> dict:
    """The other surrogates of an episode's rows: max DRAC / MDRAC, min PSD (with std) and CPI."""
    out: dict = {}
    for c, largest in (("drac", True), ("mdrac", True), ("psd", False)):
        v = r[c][rows]
        if np.isfinite(v).any():
            k = rows[int(np.nanargmax(v) if largest else np.nanargmin(v))]
            name = f"{'max' if largest else 'min'}_{c}"
            out[name] = float(r[c][k])
            out[f"{name}_std"] = _num(r[f"{c}_std"][k])
    t = r["time"][rows]
    d = np.nan_to_num(r["drac"][rows], nan=-np.inf)
    sd = np.sqrt(np.nan_to_num(r["drac_std"][rows]) ** 2 + p.madr_std_mps2 ** 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(sd > 0, (d - p.madr_mps2) / sd, np.where(d > p.madr_mps2, np.inf, -np.inf))
    prob = ndtr(z)
    dt = np.diff(t)
    step = np.r_[dt, dt[-1:] if len(dt) else [0.0]]
    span = float(step.sum())
    out["cpi"] = float((prob * step).sum() / span) if span > 0 else None
    return out


def _open(start: float, end: float, gap: float, open_at: tuple[float, float] | None) -> bool:
    """Whether an episode of a time window ``open_at`` = ``(t0, t1)`` may go on in the window
    before or after (its first or last step within ``gap`` of the window's edge)."""
    return open_at is not None and (start - gap < open_at[0] or end + gap >= open_at[1])


def threshold_episodes(r: dict[str, np.ndarray], metric: str, thr: float, prob: np.ndarray,
                       p: EventsParams, step: float,
                       open_at: tuple[float, float] | None = None) -> list[dict]:
    """Episodes of one metric (``ttc``: ``<= thr``; ``drac``: ``>= thr``) from the pair rows with
    ``prob`` (the probability of being beyond the threshold, NaN: not a candidate) at least
    ``p.evidence``, lasting at least ``p.persistence_s`` (``step``: the sampling interval one
    step stands for). ``open_at``: the rows are the time window ``(t0, t1)`` of a longer
    recording; an episode that may go on beyond it is kept whatever its length, marked
    ``open`` (:func:`join_windows` joins and checks it)."""
    v = r[metric]
    m = np.isfinite(prob) & (prob >= p.evidence)
    if not m.any():
        return []
    t = r["time"]
    key = pair_key(r["pid"][m], r["oid"][m])
    o = np.lexsort((t[m], key))
    rows = np.flatnonzero(m)[o]
    ep = _episode_ids(key[o], t[rows], p.merge_gap_s)
    out = []
    unit = "s" if metric == "ttc" else "mps2"
    for e in np.unique(ep):
        rr = rows[ep == e]
        duration = float(t[rr].max() - t[rr].min()) + step
        is_open = _open(float(t[rr].min()), float(t[rr].max()), p.merge_gap_s, open_at)
        if duration < p.persistence_s - 1e-9 and not is_open:
            continue
        k = rr[np.argmin(v[rr])] if metric == "ttc" else rr[np.argmax(v[rr])]
        sd = _num(r[f"{metric}_std"][k])
        extreme = "min" if metric == "ttc" else "max"
        attrs = {"metric": metric, "ttc_kind": r["kind"][k], "relation": r["rel"][k],
                 f"threshold_{unit}": thr, f"{extreme}_value_{unit}": float(v[k]),
                 f"{extreme}_value_std_{unit}": sd, f"time_of_{extreme}": float(t[k]),
                 "evidence": p.evidence, "p_beyond_threshold": round(float(prob[k]), 4),
                 **_surrogates_of(r, rr, p)}
        out.append({"metric": metric, "pair": (int(r["pid"][k]), int(r["oid"][k])),
                    "relation": str(r["rel"][k]), "start": float(t[rr].min()),
                    "end": float(t[rr].max()), "duration": duration, "value": float(v[k]),
                    "std": sd, "time_extreme": float(t[k]),
                    "confidence": float(np.max(prob[rr])), "attributes": attrs,
                    "open": is_open})
    return out


def pet_episodes(en: pa.Table, thr: float, p: EventsParams) -> list[dict]:
    """One episode per encroachment with ``P(PET <= thr) >= evidence`` (normal approximation).
    Where both occupied the conflict area at once (``pet`` null: a collision, or a pass so close
    that the footprints' occupancies of the area overlap) the value is the negative overlap,
    ``time_second_enter - time_first_exit``: beyond any threshold."""
    pet, std, t0, t1 = (column_numpy(en, c, missing=np.nan) for c in
                        ("pet", "pet_std", "time_first_exit", "time_second_enter"))
    pet = np.where(np.isfinite(pet), pet, np.where(t1 < t0, t1 - t0, np.nan))
    first = en.column("first_id").to_numpy()
    second = en.column("second_id").to_numpy()
    cid = en.column("conflict_id").to_numpy()
    sd = np.nan_to_num(std)
    with np.errstate(divide="ignore", invalid="ignore"):
        prob = np.where(sd > 0, ndtr((thr - pet) / sd), (pet <= thr).astype(float))
    out = []
    for k in np.flatnonzero(np.isfinite(pet) & (prob >= p.evidence)):
        s = _num(std[k])
        a, b = float(min(t0[k], t1[k])), float(max(t0[k], t1[k]))
        out.append({"metric": "pet", "pair": (int(first[k]), int(second[k])),
                    "relation": "crossing", "start": a, "end": b, "duration": b - a,
                    "value": float(pet[k]), "std": s, "time_extreme": a,
                    "confidence": float(prob[k]),
                    "attributes": {"metric": "pet", "threshold_s": thr, "value_s": float(pet[k]),
                                   "value_std_s": s, "conflict_id": int(cid[k]),
                                   "evidence": p.evidence,
                                   "p_beyond_threshold": round(float(prob[k]), 4)}})
    return out


def braking_episodes(k: pa.Table, p: EventsParams, step: float,
                     open_at: tuple[float, float] | None = None) -> list[dict]:
    """Hard braking: episodes of at least ``min_duration_s`` with ``P(a_lon <= threshold) >=
    evidence`` (normal approximation with ``a_lon_std``); ``open_at`` as in
    :func:`threshold_episodes`."""
    pid = k.column("participant_id").to_numpy()
    t, a, sd = (column_numpy(k, c, missing=np.nan) for c in ("time", "a_lon", "a_lon_std"))
    s = np.nan_to_num(sd)
    thr = p.hard_braking_mps2
    with np.errstate(divide="ignore", invalid="ignore"):
        prob = np.where(s > 0, ndtr((thr - a) / s), (a <= thr).astype(float))
    m = np.isfinite(a) & (prob >= p.evidence)
    if not m.any():
        return []
    rows = np.flatnonzero(m)
    ep = _episode_ids(pid[rows], t[rows], p.merge_gap_s)
    out = []
    for e in np.unique(ep):
        r = rows[ep == e]
        is_open = _open(float(t[r].min()), float(t[r].max()), p.merge_gap_s, open_at)
        if t[r].max() - t[r].min() < p.min_duration_s and not is_open:
            continue
        j = r[np.argmin(a[r])]
        sj = _num(sd[j])
        out.append({"metric": "a_lon", "pair": (int(pid[j]),), "relation": None,
                    "start": float(t[r].min()), "end": float(t[r].max()),
                    "duration": float(t[r].max() - t[r].min()) + step, "value": float(a[j]),
                    "std": sj, "time_extreme": float(t[j]), "confidence": float(prob[r].max()),
                    "attributes": {"metric": "a_lon", "threshold_mps2": thr,
                                   "min_value_mps2": float(a[j]), "min_value_std_mps2": sj,
                                   "time_of_min": float(t[j]), "evidence": p.evidence},
                    "open": is_open})
    return out


def _pair_of(e: dict) -> tuple[int, ...]:
    return tuple(sorted(e["pair"]))


def join_windows(episodes: list[dict], p: EventsParams, step: float) -> list[dict]:
    """The episodes of a recording from those of its disjoint time windows
    (:func:`threshold_episodes`, :func:`braking_episodes` with ``open_at``): the pieces of one
    pair's (or participant's) episode of one metric cut by window boundaries — consecutive
    critical steps at most ``merge_gap_s`` apart across the boundary — are one episode again
    (start of the first, end of the last, the duration from them as for an uncut episode, the
    extreme and its attributes of the more extreme piece, the largest confidence, the other
    surrogates' extremes over both, CPI weighted by duration); then the persistence rules
    (``persistence_s``; ``min_duration_s`` of hard braking) apply to the whole episode. Keys other
    than the episode's own (a precomputed ``collision``) come with the extreme."""
    def worse(e: dict, f: dict) -> bool:
        return e["value"] > f["value"] if e["metric"] == "drac" else e["value"] < f["value"]

    out: list[dict] = []
    for e in sorted(episodes, key=lambda e: (e["metric"], _pair_of(e), e["start"])):
        last = out[-1] if out else None
        if (last is not None and last["metric"] == e["metric"] and _pair_of(last) == _pair_of(e)
                and 0 < e["start"] - last["end"] <= p.merge_gap_s):
            out[-1] = _join(last, e, worse(e, last), step)
        else:
            out.append(dict(e))
    kept = []
    for e in out:
        e.pop("open", None)
        if e["metric"] == "a_lon":
            if e["end"] - e["start"] < p.min_duration_s:
                continue
        elif e["duration"] < p.persistence_s - 1e-9:
            continue
        kept.append(e)
    return kept


def _join(a: dict, b: dict, b_worse: bool, step: float) -> dict:
    """Episode ``a`` and its continuation ``b`` in the next window as one (:func:`join_windows`)."""
    main, other = (b, a) if b_worse else (a, b)
    attrs = dict(main["attributes"])
    oa = other["attributes"]
    for k, largest in (("max_drac", True), ("max_mdrac", True), ("min_psd", False)):
        if oa.get(k) is not None and (attrs.get(k) is None or (
                oa[k] > attrs[k] if largest else oa[k] < attrs[k])):
            attrs[k], attrs[f"{k}_std"] = oa[k], oa.get(f"{k}_std")
    if "cpi" in attrs or "cpi" in oa:
        w = [(e["attributes"].get("cpi"), e["duration"]) for e in (a, b)]
        w = [(c, d) for c, d in w if c is not None]
        attrs["cpi"] = sum(c * d for c, d in w) / sum(d for _, d in w) if w else None
    return {**main, "start": a["start"], "end": b["end"],
            "duration": float(b["end"] - a["start"]) + step,
            "confidence": max(a["confidence"], b["confidence"]), "attributes": attrs}


def encounters(episodes: list[dict], gap: float) -> list[dict]:
    """One encounter per pair and stretch of time: the pair's episodes (of any metric) that are
    closer than ``gap`` s merge. An encounter is named after its first metric of
    :data:`METRIC_ORDER` (the most extreme episode of it gives value, std, time and relation);
    its duration is the sum of its episodes' (the critical time); the others' extremes are listed
    in its attributes (``also``)."""
    by_pair: dict[frozenset, list[dict]] = {}
    for e in episodes:
        by_pair.setdefault(frozenset(e["pair"]), []).append(e)
    out = []
    for eps in by_pair.values():
        eps.sort(key=lambda e: e["start"])
        groups: list[list[dict]] = []
        for e in eps:
            if groups and e["start"] <= max(g["end"] for g in groups[-1]) + gap:
                groups[-1].append(e)
            else:
                groups.append([e])
        for g in groups:
            out.append(_merge(g))
    out.sort(key=lambda e: (e["start"], e["pair"]))
    return out


def _worse(e: dict, f: dict) -> bool:
    """Whether episode ``e`` is more extreme than ``f`` (same metric)."""
    return e["value"] > f["value"] if e["metric"] == "drac" else e["value"] < f["value"]


def _merge(group: list[dict]) -> dict:
    metric = next(m for m in METRIC_ORDER if any(e["metric"] == m for e in group))
    main = None
    for e in group:
        if e["metric"] == metric and (main is None or _worse(e, main)):
            main = e
    assert main is not None
    attrs = dict(main["attributes"])
    also = [{"metric": e["metric"], "value": e["value"], "std": e["std"],
             "time": e["time_extreme"]} for e in group if e is not main]
    if also:
        attrs["also"] = also
    return {**main, "start": min(e["start"] for e in group),
            "end": max(e["end"] for e in group),
            "duration": float(sum(e["duration"] for e in group)),
            "confidence": max(e["confidence"] for e in group), "attributes": attrs}


def wilson(hits: np.ndarray, n: int, z: float = 1.96) -> tuple[np.ndarray, np.ndarray]:
    """The Wilson score interval of ``hits`` successes in ``n`` trials."""
    p = hits / n
    den = 1 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return np.maximum(mid - half, 0.0), np.minimum(mid + half, 1.0)


__all__ = ["METRIC_ORDER", "braking_episodes", "encounters", "join_windows", "pair_key",
           "pair_rows", "pet_episodes", "threshold_episodes", "ttc_probability", "wilson"]
