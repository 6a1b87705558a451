"""``derived/criticality_summary``: the criticality of each participant and of the whole recording
in one small table — minimum TTC with its std, time exposed / time integrated TTC (TET / TIT), the
crash potential index (CPI), the largest DRAC, the smallest PSD and PET, counts below the
thresholds and the worst events (docs/derive.md "Criticality summary").

One row per participant (``scope = "participant"``) and one for the recording (``scope =
"recording"``, ``participant_id`` null). A participant's TTC at a time is the smallest over its own
rows of ``derived/interactions`` except ``follower`` rows (those are the follower's): its lane
leader (1D), its neighbours and conflicting participants (2D). Definitions:

- **TET** (Minderhoud & Bovy 2001) ``= Σ_t dt · 1[TTC_t <= TTC*]``, **TIT** ``= Σ_t dt ·
  (TTC* − TTC_t)`` over the samples with ``TTC_t <= TTC*``; ``dt`` is the participant's sampling
  interval at t (to its next sample, at most ``max_gap_s``). The recording's are the sums over
  participants. ``TTC*`` is ``ttc_s`` (default: the events' threshold: recording.json
  ``thresholds.ttc_s``, else 1.5 s).
- **CPI** (Cunto & Saccomanno 2008) ``= Σ_t dt · P(DRAC_t > MADR) / T``: the share of the
  participant's observed time ``T`` in which the deceleration it would need exceeds the maximum
  available deceleration, a normal ``MADR ~ N(madr_mps2, madr_std_mps2²)`` (8.45 ± 1.4 m/s², dry
  asphalt) convolved with the DRAC's own std. The recording's is time-weighted over participants.
- **max DRAC**, **min PSD**: over the same rows; **min PET**: over ``derived/encroachments`` rows
  the participant is in; counts: samples with ``TTC <= TTC*``, derived near misses and
  hard-braking events the participant is in; ``worst_events``: the ids of up to five of those
  near misses and conflicts, most critical first (the largest collision probability, then the
  smallest TTC/PET, then those from DRAC alone, largest first).

Uncertainty: ``min_ttc_std`` is the std of the minimum's row. TET and TIT take their std from
``samples`` Monte Carlo draws of every TTC below ``TTC* + 4 σ``, ``TTC_t + σ_t z`` with one ``z``
per pair episode (consecutive samples of one pair): the errors of a smoothed track are correlated
over seconds, so fully correlated within an episode is the conservative choice (independent draws
per sample would shrink the std by the square root of the episode's length); episodes are
independent. CPI's std treats its samples as independent Bernoulli terms,
``sqrt(Σ dt² p (1 − p)) / T``.
"""

from __future__ import annotations

import json
from collections.abc import Iterable

import numpy as np
import pyarrow as pa
from pydantic import Field
from scipy.special import ndtr

from aveas_format.derive._samples import find_rows, segments, string_values
from aveas_format.derive.events import DEFAULT_THRESHOLD_S
from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.io.arrow import column_numpy
from aveas_format.schema.columns import MAY, MUST, col, enum_col, gaussian
from aveas_format.schema.tables import derived_table

#: how many event ids ``worst_events`` lists
N_WORST = 5


class CriticalityParams(Params):
    """Parameters of ``criticality_summary``."""

    ttc_s: float | None = Field(None, gt=0, description="TTC threshold TTC* (s) of TET, TIT and "
                                "the counts; default recording.json thresholds.ttc_s, else 1.5")
    madr_mps2: float = Field(8.45, gt=0, description="mean maximum available deceleration (m/s²) "
                             "of CPI (Cunto & Saccomanno 2008, dry asphalt)")
    madr_std_mps2: float = Field(1.4, ge=0, description="its standard deviation (m/s²)")
    max_gap_s: float = Field(1.0, gt=0, description="a longer interval between a participant's "
                             "samples counts as this long in TET, TIT and CPI")
    samples: int = Field(64, ge=0, description="Monte Carlo draws of the TET/TIT std (0: none)")
    seed: int = Field(0, description="random seed of the draws")


def _ttc_threshold(rec, p: CriticalityParams) -> float:
    if p.ttc_s is not None:
        return float(p.ttc_s)
    th = rec.meta.thresholds
    return float(th.ttc_s) if th is not None and th.ttc_s else DEFAULT_THRESHOLD_S


def _sample_dt(rec, max_gap: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(participant_id, time, dt)`` of every states row (sorted by participant, time): the
    interval to the participant's next sample (the previous one for its last), capped."""
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = column_numpy(s, "time", missing=np.nan)
    o = np.lexsort((t, pid))
    pid, t = pid[o], t[o]
    dt = np.full(len(t), np.nan)
    if len(t) > 1:
        nxt = np.diff(t)
        same = pid[1:] == pid[:-1]
        dt[:-1] = np.where(same, nxt, np.nan)
        last = np.r_[~same, True]
        prev = np.r_[np.nan, np.where(same, nxt, np.nan)]
        dt = np.where(last, prev, dt)
    dt = np.minimum(np.nan_to_num(dt, nan=0.0), max_gap)
    return pid, t, dt


def _lookup_dt(pid_s, t_s, dt_s, pid, t) -> np.ndarray:
    """dt of the states rows at (pid, t) (0 where there is none)."""
    if not len(pid):
        return np.zeros(0)
    pos, ok = find_rows(pid_s, t_s, pid, t)
    return np.where(ok, dt_s[pos], 0.0) if len(pid_s) else np.zeros(len(pid))


def _group_min(key: np.ndarray, v: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per group ``0..n-1``: the row of the smallest finite ``v`` (-1 where none) and that value."""
    best = np.full(n, -1, np.int64)
    val = np.full(n, np.nan)
    fin = np.flatnonzero(np.isfinite(v))
    if len(fin):
        o = fin[np.lexsort((v[fin], key[fin]))]
        first = np.r_[True, key[o][1:] != key[o][:-1]]
        best[key[o][first]] = o[first]
        val[key[o][first]] = v[o][first]
    return best, val


def _episode_draws(key: np.ndarray, t: np.ndarray, gap: float, K: int, rng) -> np.ndarray:
    """``(K, rows)`` standard normals shared within each episode of ``key`` (rows sorted by key,
    time; a new episode at a new key or a time gap)."""
    seg_len = segments(key, t, gap)[1]
    z = rng.standard_normal((K, len(seg_len)))
    return np.repeat(z, seg_len, axis=1)


def compute(rec, p: CriticalityParams, core: tuple[float, float] | None = None) -> pa.Table:
    """The ``derived/criticality_summary`` table of ``rec``; ``core`` ``(t0, t1)``: of the states
    in ``[t0, t1)`` only, their sampling intervals from all states (a time window of a longer
    recording, derive.streamed)."""
    thr = _ttc_threshold(rec, p)
    spid, st, sdt = _sample_dt(rec, p.max_gap_s)
    if core is not None:
        keep = (st >= core[0]) & (st < core[1])
        spid, st, sdt = spid[keep], st[keep], sdt[keep]
    parts = rec.participants.column("participant_id").to_numpy()
    ids = np.unique(np.r_[parts, spid]).astype(np.int64)
    n = len(ids)
    T = np.bincount(np.searchsorted(ids, spid), weights=sdt, minlength=n) if len(spid) else np.zeros(n)
    out: dict[str, np.ndarray] = {
        "duration_s": T,
        **{k: np.full(n, np.nan) for k in ("min_ttc", "min_ttc_std", "min_ttc_time", "tet",
                                            "tet_std", "tit", "tit_std", "cpi", "cpi_std",
                                            "max_drac", "max_drac_std", "min_psd", "min_psd_std",
                                            "min_pet", "min_pet_std")},
        "min_ttc_other_id": np.full(n, -1, np.int64),
        "ttc_samples_below": np.zeros(n, np.int64),
    }
    out["min_ttc_kind"] = np.full(n, None, object)
    it = rec.derived.get("interactions")
    if it is not None and it.num_rows:
        _interaction_measures(it, ids, out, thr, spid, st, sdt, p)
    en = rec.derived.get("encroachments")
    if en is not None and en.num_rows:
        _pet_measures(en, ids, out)
    counts, worst, rec_worst = event_measures(rec.events, ids)
    # --- the recording row ---------------------------------------------------------------------
    total_T = float(T.sum())

    def nanmin_at(v, sd, other=None):
        if not np.isfinite(v).any():
            return np.nan, np.nan, -1
        k = int(np.nanargmin(v))
        return float(v[k]), float(sd[k]), k

    rv = {"duration_s": total_T}
    rv["min_ttc"], rv["min_ttc_std"], k = nanmin_at(out["min_ttc"], out["min_ttc_std"])
    rv["min_ttc_time"] = float(out["min_ttc_time"][k]) if k >= 0 else np.nan
    rv["min_ttc_other_id"] = int(out["min_ttc_other_id"][k]) if k >= 0 else -1
    rv["min_ttc_kind"] = out["min_ttc_kind"][k] if k >= 0 else None
    rv["tet"] = float(np.nansum(out["tet"]))
    rv["tet_std"] = float(np.sqrt(np.nansum(out["tet_std"] ** 2)))
    rv["tit"] = float(np.nansum(out["tit"]))
    rv["tit_std"] = float(np.sqrt(np.nansum(out["tit_std"] ** 2)))
    cpi_num = np.nan_to_num(out["cpi"]) * T
    cpi_var = (np.nan_to_num(out["cpi_std"]) * T) ** 2
    rv["cpi"] = float(cpi_num.sum() / total_T) if total_T > 0 else np.nan
    rv["cpi_std"] = float(np.sqrt(cpi_var.sum()) / total_T) if total_T > 0 else np.nan
    if np.isfinite(out["max_drac"]).any():
        k = int(np.nanargmax(out["max_drac"]))
        rv["max_drac"], rv["max_drac_std"] = float(out["max_drac"][k]), float(out["max_drac_std"][k])
    else:
        rv["max_drac"] = rv["max_drac_std"] = np.nan
    rv["min_psd"], rv["min_psd_std"], _ = nanmin_at(out["min_psd"], out["min_psd_std"])
    rv["min_pet"], rv["min_pet_std"], _ = nanmin_at(out["min_pet"], out["min_pet_std"])
    rv["ttc_samples_below"] = int(out["ttc_samples_below"].sum())
    # events: the recording counts each event once
    for k in ("near_misses", "conflicts", "hard_braking"):
        rv[k] = counts.get(f"recording_{k}", 0)
    return summary_table(ids, out, counts, worst, rv, rec_worst)


def _interaction_measures(it: pa.Table, ids: np.ndarray, out: dict, thr: float, spid, st, sdt,
                          p: CriticalityParams) -> None:
    rel = string_values(it, "relation")
    pid = it.column("participant_id").to_numpy()
    oid = it.column("other_id").to_numpy()
    t, ttc, sd = (column_numpy(it, c, missing=np.nan) for c in ("time", "ttc", "ttc_std"))
    own = rel != "follower"
    pid, oid, t, ttc, sd = pid[own], oid[own], t[own], ttc[own], sd[own]
    kind = string_values(it, "ttc_kind")[own]
    cols = {c: (column_numpy(it, c, missing=np.nan)[own] if c in it.column_names
                else np.full(len(pid), np.nan))
            for c in ("drac", "drac_std", "psd", "psd_std")}
    g = np.searchsorted(ids, pid)
    n = len(ids)
    # --- minimum TTC --------------------------------------------------------------------------
    best, val = _group_min(g, ttc, n)
    has = best >= 0
    b = best[has]
    out["min_ttc"][has], out["min_ttc_std"][has] = val[has], sd[b]
    out["min_ttc_time"][has], out["min_ttc_other_id"][has] = t[b], oid[b]
    out["min_ttc_kind"][has] = kind[b]
    # --- max DRAC, min PSD ----------------------------------------------------------------------
    bd, vd = _group_min(g, -cols["drac"], n)
    hd = bd >= 0
    out["max_drac"][hd], out["max_drac_std"][hd] = -vd[hd], cols["drac_std"][bd[hd]]
    bp, vp = _group_min(g, cols["psd"], n)
    hp = bp >= 0
    out["min_psd"][hp], out["min_psd_std"][hp] = vp[hp], cols["psd_std"][bp[hp]]
    # --- the participant's TTC per time step: the smallest over its rows ---------------------
    fin = np.isfinite(ttc)
    o = np.flatnonzero(fin)
    o = o[np.lexsort((ttc[o], t[o], pid[o]))]
    first = np.r_[True, (pid[o][1:] != pid[o][:-1]) | (t[o][1:] != t[o][:-1])] if len(o) else o
    step = o[first] if len(o) else o
    dt = _lookup_dt(spid, st, sdt, pid[step], t[step])
    below = ttc[step] <= thr
    gs = g[step]
    out["ttc_samples_below"] = np.bincount(gs[below], minlength=n).astype(np.int64)
    out["tet"] = np.bincount(gs, weights=dt * below, minlength=n)
    out["tit"] = np.bincount(gs, weights=dt * np.where(below, thr - ttc[step], 0.0), minlength=n)
    _tet_std(out, step, pid, oid, t, ttc, sd, dt, gs, thr, n, p)
    # --- CPI: P(DRAC > MADR) over the time steps ---------------------------------------------
    drac_all, dstd_all = cols["drac"], np.nan_to_num(cols["drac_std"])
    od = np.flatnonzero(np.isfinite(drac_all))
    if len(od):
        od = od[np.lexsort((-drac_all[od], t[od], pid[od]))]
        f2 = np.r_[True, (pid[od][1:] != pid[od][:-1]) | (t[od][1:] != t[od][:-1])]
        sd_ = od[f2]
        s2 = np.sqrt(dstd_all[sd_] ** 2 + p.madr_std_mps2 ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(s2 > 0, (drac_all[sd_] - p.madr_mps2) / s2,
                         np.where(drac_all[sd_] > p.madr_mps2, np.inf, -np.inf))
        pr = ndtr(z)
        dtd = _lookup_dt(spid, st, sdt, pid[sd_], t[sd_])
        num = np.bincount(g[sd_], weights=pr * dtd, minlength=n)
        var = np.bincount(g[sd_], weights=pr * (1 - pr) * dtd ** 2, minlength=n)
    else:
        num = var = np.zeros(n)
    T = out["duration_s"]
    with np.errstate(divide="ignore", invalid="ignore"):
        out["cpi"] = np.where(T > 0, num / T, np.nan)
        out["cpi_std"] = np.where(T > 0, np.sqrt(var) / T, np.nan)


def _tet_std(out, step, pid, oid, t, ttc, sd, dt, gs, thr, n, p: CriticalityParams) -> None:
    """Monte Carlo std of TET and TIT (one normal per pair episode; module docstring)."""
    sdv = np.nan_to_num(sd[step])
    near = ttc[step] <= thr + 4 * sdv
    out["tet_std"] = np.zeros(n)
    out["tit_std"] = np.zeros(n)
    if p.samples == 0 or not near.any():
        return
    r = step[near]
    o = np.lexsort((t[r], oid[r], pid[r]))
    r = r[o]
    dtr, sdr, gr = dt[near][o], sdv[near][o], gs[near][o]
    pair = pid[r].astype(np.int64) * (int(oid[r].max()) + 1) + oid[r]
    rng = np.random.default_rng(p.seed)
    z = _episode_draws(pair, t[r], p.max_gap_s, p.samples, rng)
    draw = ttc[r][None, :] + sdr[None, :] * z
    inside = (draw <= thr) & (draw >= 0)
    tet_k = np.zeros((p.samples, n))
    tit_k = np.zeros((p.samples, n))
    for k in range(p.samples):  # K small, columnar inside
        tet_k[k] = np.bincount(gr, weights=dtr * inside[k], minlength=n)
        tit_k[k] = np.bincount(gr, weights=dtr * np.where(inside[k], thr - draw[k], 0.0),
                               minlength=n)
    # rows further than 4 σ below the threshold are exactly inside in every draw; their
    # contribution is constant and adds no variance
    out["tet_std"] = tet_k.std(0, ddof=1)
    out["tit_std"] = tit_k.std(0, ddof=1)


def _pet_measures(en: pa.Table, ids: np.ndarray, out: dict) -> None:
    pet, sd = (column_numpy(en, c, missing=np.nan) for c in ("pet", "pet_std"))
    for c in ("first_id", "second_id"):
        who = en.column(c).to_numpy()
        g = np.searchsorted(ids, who)
        ok = (g < len(ids)) & (ids[np.minimum(g, len(ids) - 1)] == who)
        v = np.where(ok, pet, np.nan)
        best, val = _group_min(np.where(ok, g, 0), v, len(ids))
        better = (best >= 0) & ~(out["min_pet"] <= val)
        out["min_pet"] = np.where(better, val, out["min_pet"])
        out["min_pet_std"] = np.where(better, sd[np.maximum(best, 0)], out["min_pet_std"])


def _severity(attrs: dict, p: float | None) -> tuple[float, int, float]:
    """Sort key of a critical event, most critical first: by collision probability (larger
    first), then by TTC or PET (smaller first), then those from DRAC alone (larger first)."""
    pk = -(p if p is not None else 0.0)
    v = attrs.get("min_value_s", attrs.get("value_s"))
    if v is not None:
        return (pk, 0, float(v))
    return (pk, 1, -float(attrs.get("max_value_mps2", 0.0) or 0.0))


#: the kinds of critical events (``worst_events``), counted as the summary's columns
CRITICAL = {"near_miss": "near_misses", "conflict": "conflicts"}


def event_measures(ev: pa.Table | None, ids: np.ndarray
                   ) -> tuple[dict, list[list[int]], list[int]]:
    """Counts of the derived near misses, conflicts and hard-braking events of the events table
    ``ev`` per participant of ``ids`` (and for the recording: ``recording_near_misses``, ...) and
    the worst critical events' ids (per participant, of the recording)."""
    n = len(ids)
    counts = {k: np.zeros(n, np.int64) for k in ("near_misses", "conflicts", "hard_braking")}
    worst: list[list[tuple]] = [[] for _ in range(n)]
    allw: list[tuple] = []
    if ev is not None and ev.num_rows:
        d = ev.select([c for c in ("event_id", "kind", "origin", "participant_ids", "attributes",
                                   "collision_probability")
                       if c in ev.column_names]).to_pydict()
        attrs_all = d.get("attributes") or [None] * ev.num_rows
        probs = d.get("collision_probability") or [None] * ev.num_rows
        for eid, kind, origin, pids, attr, prob in zip(d["event_id"], d["kind"], d["origin"],
                                                       d["participant_ids"], attrs_all, probs):
            kind = str(kind)
            if str(origin) != "derived" or kind not in (*CRITICAL, "hard_braking"):
                continue
            a = json.loads(attr) if attr else {}
            key = CRITICAL.get(kind, "hard_braking")
            counts[f"recording_{key}"] = counts.get(f"recording_{key}", 0) + 1
            if kind in CRITICAL:
                allw.append((_severity(a, prob), int(eid)))
            for q in pids or []:
                g = int(np.searchsorted(ids, q))
                if g < n and ids[g] == q:
                    counts[key][g] += 1
                    if kind in CRITICAL:
                        worst[g].append((_severity(a, prob), int(eid)))
    top = [[e for _, e in sorted(w)[:N_WORST]] for w in worst]
    return counts, top, [e for _, e in sorted(allw)[:N_WORST]]


def _f(v: Iterable) -> pa.Array:
    v = np.asarray(list(v) if not isinstance(v, np.ndarray) else v, float)
    return pa.array(v, pa.float64(), mask=~np.isfinite(v))


def summary_table(ids, out, counts, worst, rv, rec_worst) -> pa.Table:
    """The ``criticality_summary`` table: one row per participant (``ids``) from the per-participant
    measures ``out``, event ``counts`` and worst events, and the recording's row."""
    n = len(ids)
    floats = ("duration_s", "min_ttc", "min_ttc_std", "min_ttc_time", "tet", "tet_std", "tit",
              "tit_std", "cpi", "cpi_std", "max_drac", "max_drac_std", "min_psd", "min_psd_std",
              "min_pet", "min_pet_std")
    cols: dict[str, pa.Array] = {
        "scope": pa.array(["participant"] * n + ["recording"], pa.string()),
        "participant_id": pa.array(list(ids.tolist()) + [None], pa.int64()),
    }
    for c in floats:
        cols[c] = _f(np.r_[out[c], rv[c]])
    other = np.r_[out["min_ttc_other_id"], rv["min_ttc_other_id"]]
    cols["min_ttc_other_id"] = pa.array(other, pa.int64(), mask=other < 0)
    cols["min_ttc_kind"] = pa.array(list(out["min_ttc_kind"]) + [rv["min_ttc_kind"]], pa.string())
    cols["ttc_samples_below"] = pa.array(np.r_[out["ttc_samples_below"], rv["ttc_samples_below"]],
                                         pa.int64())
    for k in ("near_misses", "conflicts", "hard_braking"):
        cols[k] = pa.array(np.r_[counts.get(k, np.zeros(n, np.int64)), rv.get(k, 0)], pa.int64())
    cols["worst_events"] = pa.array(list(worst) + [rec_worst], pa.list_(pa.int64()))
    return pa.table(cols)


def _g(name: str, unit: str | None, doc: str, **kw):
    return gaussian(name, unit, MUST, doc, **kw)


TABLE = derived_table(
    "criticality_summary",
    doc="Criticality per participant and for the whole recording: minimum TTC with its std, "
    "TET/TIT, CPI, the largest DRAC, the smallest PSD and PET, counts below the thresholds and "
    "the worst events.",
    key=("scope", "participant_id"),
    sort=("scope", "participant_id"),
    columns=(
        enum_col("scope", ("participant", "recording"), MUST, "what the row summarises",
                 nullable=False),
        col("participant_id", "int64", MUST, "the participant (null in the recording's row)",
            minimum=0),
        col("duration_s", "float64", MUST, "observed time (s): the sum of the sampling "
            "intervals", "s", minimum=0.0),
        *_g("min_ttc", "s", "smallest TTC over the participant's rows of derived/interactions "
            "(not follower rows)", minimum=0.0),
        col("min_ttc_time", "float64", MUST, "time of the minimum TTC", "s"),
        col("min_ttc_other_id", "int64", MUST, "the other participant of the minimum TTC",
            minimum=0),
        col("min_ttc_kind", "string", MUST, "ttc_kind of the minimum TTC"),
        *_g("tet", "s", "time exposed TTC: time with TTC <= the threshold", minimum=0.0),
        *_g("tit", "s²", "time integrated TTC: integral of (threshold - TTC) while below it",
            minimum=0.0),
        *_g("cpi", None, "crash potential index: share of the observed time in which DRAC "
            "exceeds the maximum available deceleration", minimum=0.0, maximum=1.0),
        *_g("max_drac", "m/s²", "largest DRAC", minimum=0.0),
        *_g("min_psd", None, "smallest proportion of stopping distance", minimum=0.0),
        *_g("min_pet", "s", "smallest PET (derived/encroachments)", minimum=0.0),
        col("ttc_samples_below", "int64", MUST, "samples (time steps) with TTC <= the threshold",
            minimum=0),
        col("near_misses", "int64", MUST, "derived near-miss events (collision probability at "
            "least the events' near_miss_probability)", minimum=0),
        col("conflicts", "int64", MAY, "derived conflicts (critical by TTC, PET or DRAC, averted "
            "by the recorded behaviour)", minimum=0),
        col("hard_braking", "int64", MUST, "derived hard-braking events", minimum=0),
        col("worst_events", "list<int64>", MUST, "ids (events.event_id) of up to five near "
            "misses and conflicts, most critical first (the largest collision probability, then "
            "the smallest TTC or PET)"),
    ),
)

CRITICALITY_SUMMARY = register(Derivation(
    name="criticality_summary",
    spec=TABLE,
    version="1.1.0",
    params=CriticalityParams,
    fn=compute,
    needs={"states": ("participant_id", "time"), "participants": ("participant_id",)},
    # events are read (counts, worst events) but not hashed as an input: they follow from the
    # interactions and encroachments, which are, and the events table's bytes change when a
    # written recording is written again (its schema metadata), which would mark the summary stale
    optional=("derived/interactions", "derived/encroachments"),
    after=("interactions", "encroachments", "events"),
    doc="per participant and recording: minimum TTC, TET/TIT, CPI, max DRAC, min PSD/PET, "
        "counts and worst events",
    method=lambda p: "tet_tit_cpi",
))
