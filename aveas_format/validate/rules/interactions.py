"""Interactions between participants: overlapping footprints and duplicated tracks.

Both rules share one vectorised pass (cached in ``ctx.cache``) over compact per-sample arrays that a
collector gathers batch by batch (so streamed recordings need ~70 bytes per sample, not the whole
states table), processed in windows of whole frames: samples are put on the frame grid of
``nominal_rate_hz`` (positions moved to the frame time with their velocity), hashed into grid cells
as large as the largest footprint, and every pair of samples in the same or a neighbouring cell of
the same frame is a candidate; oriented footprints are then tested with the separating-axis theorem.
No Python loop runs over samples or pairs.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyarrow as pa

from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hits, collector, rule
from aveas_format.validate.views import StatesView, num

#: footprints larger than this (trains) are left out of the pair search
_MAX_CELL = 50.0


def _ramp(counts: np.ndarray) -> np.ndarray:
    """0..c-1 for each count c, concatenated."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    starts = np.repeat(np.cumsum(counts) - counts, counts)
    return np.arange(total) - starts


def candidate_pairs(frame: np.ndarray, x: np.ndarray, y: np.ndarray, cell: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (a, b), a != b, of samples in the same frame whose grid cells touch."""
    n = len(x)
    if n < 2:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cx = np.floor((x - x.min()) / cell).astype(np.int64) + 1
    cy = np.floor((y - y.min()) / cell).astype(np.int64) + 1
    nx, ny = int(cx.max()) + 3, int(cy.max()) + 3
    f = frame.astype(np.int64) - int(frame.min())
    key = (f * nx + cx) * ny + cy
    order = np.argsort(key, kind="stable")
    ks = key[order]
    out_a, out_b = [], []
    # same cell: every later element of the run
    run_end = np.searchsorted(ks, ks, side="right")
    pos = np.arange(n)
    cnt = run_end - pos - 1
    a = np.repeat(pos, cnt)
    out_a.append(a)
    out_b.append(a + 1 + _ramp(cnt))
    # forward neighbour cells (each unordered cell pair once)
    for dx, dy in ((1, -1), (1, 0), (1, 1), (0, 1)):
        target = ks + dx * ny + dy
        lo = np.searchsorted(ks, target, side="left")
        hi = np.searchsorted(ks, target, side="right")
        cnt = hi - lo
        out_a.append(np.repeat(pos, cnt))
        out_b.append(np.repeat(lo, cnt) + _ramp(cnt))
    a = order[np.concatenate(out_a)]
    b = order[np.concatenate(out_b)]
    return a, b


#: samples per window of frames in the pair search (bounds its temporary arrays)
_WINDOW = 1_000_000


def _collect(ctx: Context) -> dict[str, np.ndarray] | None:
    """The compact per-sample arrays the pair search needs, from one batch of states: samples
    moved to their frame time, with footprint sizes, keyed by participant and file row."""
    sv: StatesView | None = ctx.states_view
    pv = ctx.participants_view
    if sv is None or ctx.meta is None or pv.length is None or pv.width is None or not sv.n:
        return None
    x, y, h = sv.col("x"), sv.col("y"), sv.col("heading")
    if x is None or y is None or h is None:
        return None
    vx, vy = sv.col("vx"), sv.col("vy")
    rate = ctx.meta.nominal_rate_hz
    frame = np.floor(sv.t * rate + 0.5).astype(np.int64)
    shift = frame / rate - sv.t
    xf = x + (np.nan_to_num(vx) * shift if vx is not None else 0)
    yf = y + (np.nan_to_num(vy) * shift if vy is not None else 0)
    ok = sv.pidx >= 0
    L = np.where(ok, pv.length[np.maximum(sv.pidx, 0)], np.nan)
    W = np.where(ok, pv.width[np.maximum(sv.pidx, 0)], np.nan)
    diag = np.hypot(L, W)
    use = ok & np.isfinite(xf) & np.isfinite(yf) & np.isfinite(h) & (diag > 0) & (diag <= _MAX_CELL)
    idx = np.flatnonzero(use)
    rows = sv.row[idx]
    file_rows = ctx.file_rows.get("states")
    if file_rows is not None:
        rows = file_rows[rows]
    # compact types (~52 bytes per sample): the search needs positions in float64 only
    small = len(rows) == 0 or (rows.max() < 2**31 and np.abs(frame[idx]).max() < 2**31)
    return {"pid": sv.pid[idx], "t": sv.t[idx],
            "row": rows.astype(np.int32 if small else np.int64),
            "frame": frame[idx].astype(np.int32 if small else np.int64),
            "x": xf[idx], "y": yf[idx], "h": h[idx].astype(np.float32),
            "L": L[idx].astype(np.float32), "W": W[idx].astype(np.float32),
            # frame range of every participant (all its samples), for duplicate_track
            "seg_pid": sv.pid[sv.starts], "seg_first": frame[sv.starts],
            "seg_last": frame[sv.ends - 1]}


def _merge(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray] | None:
    """Concatenate the batches' arrays key by key, releasing each batch's array as it goes (peak:
    the merged arrays plus one key's parts)."""
    if not parts:
        return None
    out = {}
    for k in list(parts[0]):
        out[k] = np.concatenate([p.pop(k) for p in parts])
    parts.clear()
    return out


collector("interactions.samples", merge=_merge)(_collect)


def _pairs(ctx: Context):
    """Pair statistics shared by the interaction rules (cached)."""
    if "interactions.pairs" in ctx.cache:
        return ctx.cache["interactions.pairs"]
    ctx.cache["interactions.pairs"] = res = _compute_pairs(ctx)
    return res


def _window_pairs(S: dict[str, np.ndarray], idx: np.ndarray, cell: float, shrink: float):
    """Near pairs (a, b as sample indices, a's participant id < b's) among samples ``idx`` (whole
    frames), with the separating-axis overlap depth of their footprints and centre distance."""
    a, b = candidate_pairs(S["frame"][idx], S["x"][idx], S["y"][idx], cell)
    a, b = idx[a], idx[b]
    pid = S["pid"]
    keep = pid[a] != pid[b]
    a, b = a[keep], b[keep]
    swap = pid[a] > pid[b]
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    x, y = S["x"], S["y"]
    dx, dy = x[b] - x[a], y[b] - y[a]
    dist = np.hypot(dx, dy)
    La, Wa = S["L"][a].astype(np.float64), S["W"][a].astype(np.float64)
    Lb, Wb = S["L"][b].astype(np.float64), S["W"][b].astype(np.float64)
    near = dist < 0.5 * (np.hypot(La, Wa) + np.hypot(Lb, Wb))
    a, b, dx, dy, dist = a[near], b[near], dx[near], dy[near], dist[near]
    La, Wa, Lb, Wb = La[near], Wa[near], Lb[near], Wb[near]
    # separating-axis test of the two oriented footprints, shrunk by the tolerance
    hl_a = np.maximum(La / 2 - shrink, 0.01)
    hw_a = np.maximum(Wa / 2 - shrink, 0.01)
    hl_b = np.maximum(Lb / 2 - shrink, 0.01)
    hw_b = np.maximum(Wb / 2 - shrink, 0.01)
    ha, hb = S["h"][a].astype(np.float64), S["h"][b].astype(np.float64)
    ua = np.stack([np.cos(ha), np.sin(ha)])
    na = np.stack([-np.sin(ha), np.cos(ha)])
    ub = np.stack([np.cos(hb), np.sin(hb)])
    nb = np.stack([-np.sin(hb), np.cos(hb)])
    d = np.stack([dx, dy])
    depth = np.full(len(a), np.inf)
    for k in (ua, na, ub, nb):
        ra = hl_a * np.abs((ua * k).sum(0)) + hw_a * np.abs((na * k).sum(0))
        rb = hl_b * np.abs((ub * k).sum(0)) + hw_b * np.abs((nb * k).sum(0))
        depth = np.minimum(depth, ra + rb - np.abs((d * k).sum(0)))
    return a, b, depth, dist


def _compute_pairs(ctx: Context):
    S = ctx.collected.get("interactions.samples")
    if S is None or ctx.meta is None or len(S["pid"]) < 2:
        return None
    ic = ctx.config.interactions
    cell = float(np.hypot(S["L"], S["W"]).max())
    # windows of whole frames, ~_WINDOW samples each
    order = np.argsort(S["frame"], kind="stable")
    fs = S["frame"][order]
    cuts = [0]
    while cuts[-1] < len(order):
        j = min(cuts[-1] + _WINDOW, len(order))
        if j < len(order):
            j = int(np.searchsorted(fs, fs[j - 1], side="right"))
        cuts.append(j)
    del fs
    parts = [_window_pairs(S, order[lo:hi], cell, ic.overlap_depth_m)
             for lo, hi in zip(cuts[:-1], cuts[1:])]
    a, b, depth, dist = (np.concatenate([p[k] for p in parts]) for k in range(4))
    overlap = depth > 0
    pid = S["pid"]
    pv = ctx.participants_view
    # exclusions: attached participants, accidents
    att = num(pv.table, "attached_to", "participants")
    excluded = np.zeros(len(a), bool)
    if att is not None:
        ia, ib = pv.index_of(pid[a]), pv.index_of(pid[b])
        aa = np.where(ia >= 0, att[np.maximum(ia, 0)], np.nan)
        ab = np.where(ib >= 0, att[np.maximum(ib, 0)], np.nan)
        excluded |= (aa == pid[b]) | (ab == pid[a])
    excluded |= in_accident(ctx, pid[a], pid[b], S["t"][a])
    # duplicate tracks: close for most of the common time
    W = S["W"]
    close_d = np.minimum(ic.duplicate_distance_m, 0.5 * np.minimum(W[a], W[b]).astype(np.float64))
    close = dist < close_d
    seg_pid = S["seg_pid"]
    nseg = len(seg_pid)
    seg_a = np.searchsorted(seg_pid, pid[a])
    seg_b = np.searchsorted(seg_pid, pid[b])
    pair_key = seg_a.astype(np.int64) * nseg + seg_b
    return {"a": a, "b": b, "depth": depth, "dist": dist, "overlap": overlap & ~excluded,
            "close": close, "key": pair_key, "rate": ctx.meta.nominal_rate_hz, "nseg": nseg,
            "excluded": excluded}


def in_accident(ctx: Context, pa_: np.ndarray, pb: np.ndarray, t: np.ndarray) -> np.ndarray:
    """True where an `accident` event names both participants and covers the time."""
    e = ctx.table("events")
    out = np.zeros(len(pa_), bool)
    if e is None or "kind" not in e.column_names or "participant_ids" not in e.column_names:
        return out
    ts, te = num(e, "time_start", "events"), num(e, "time_end", "events")
    if ts is None or te is None or not pa.types.is_list(e.column("participant_ids").type):
        return out
    kinds = e.column("kind").cast(pa.string()).to_pylist()
    ids = e.column("participant_ids").to_pylist()
    for k in range(e.num_rows):  # events are few; each test is vectorised over the pairs
        if kinds[k] != "accident" or not ids[k]:
            continue
        members = np.asarray(ids[k], dtype=np.int64)
        out |= np.isin(pa_, members) & np.isin(pb, members) & (t >= ts[k]) & (t <= te[k])
    return out


def _duplicates(ctx: Context, p) -> np.ndarray:
    """Pair keys of duplicated tracks."""
    if "interactions.dups" in ctx.cache:
        return ctx.cache["interactions.dups"]
    S = ctx.collected["interactions.samples"]
    ic = ctx.config.interactions
    keys = p["key"][p["close"]]
    dup = np.zeros(0, np.int64)
    if len(keys):
        u, cnt = np.unique(keys, return_counts=True)
        # common frames of each pair: overlap of the two participants' frame ranges
        first, last = S["seg_first"], S["seg_last"]
        sa, sb = u // p["nseg"], u % p["nseg"]
        common = np.minimum(last[sa], last[sb]) - np.maximum(first[sa], first[sb]) + 1
        ok = (cnt >= ic.duplicate_share * np.maximum(common, 1)) & (cnt / p["rate"] >= ic.duplicate_min_s)
        dup = u[ok]
    ctx.cache["interactions.dups"] = dup
    return dup


def _pair_hits(S, p, mask: np.ndarray, value: np.ndarray, field: str) -> Hits:
    """One finding per pair of the ``mask`` rows: at its first sample (by frame), with the number
    of frames and the largest ``value`` (as ``field``), in file-row order."""
    a, b, key = p["a"][mask], p["b"][mask], p["key"][mask]
    val = value[mask]
    order = np.lexsort((S["frame"][a], key))
    a, b, key, val = a[order], b[order], key[order], val[order]
    first = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
    counts = np.diff(np.r_[first, len(key)])
    peak = np.maximum.reduceat(val, first) if len(val) else val
    i, j = a[first], b[first]
    o = np.argsort(S["row"][i], kind="stable")
    i, j, counts, peak = i[o], j[o], counts[o], peak[o]
    return Hits(total=len(i), arrays={"row": S["row"][i], "participant_id": S["pid"][i],
                                     "other_id": S["pid"][j], "time": S["t"][i],
                                     "x": np.round(S["x"][i], 2), "y": np.round(S["y"][i], 2),
                                     field: np.round(peak, 3), "n_frames": counts},
               const={"file": "states.parquet", "table": "states", "column": "x,y"})


@rule("interactions.overlap", "warning", "Footprints of two participants overlap",
      "states.parquet: row {row}: participant {participant_id} and {other_id} overlap by {value} m "
      "at {time} s ({n_frames} frames): a tracking error unless it was an accident",
      needs=("interactions.samples",),
      enforces=quality("no_overlap"))
def overlap(ctx: Context) -> Iterator[Hits]:
    """The footprints (length x width around the reference point, oriented by heading, shrunk by
    ``[interactions] overlap_depth_m``) of two participants overlap at the same time. Exempt: a
    participant ``attached_to`` the other, times covered by an ``accident`` event naming both, and
    pairs reported by interactions.duplicate_track. One finding per pair."""
    p = _pairs(ctx)
    if p is None:
        return
    S = ctx.collected["interactions.samples"]
    mask = p["overlap"] & ~np.isin(p["key"], _duplicates(ctx, p))
    if not mask.any():
        return
    yield _pair_hits(S, p, mask, p["depth"], "value")


@rule("interactions.duplicate_track", "warning", "One object tracked twice",
      "states.parquet: row {row}: participants {participant_id} and {other_id} move together "
      "(centres within {distance} m in {n_frames} frames of their common time): one object "
      "tracked twice", needs=("interactions.samples",),
      enforces=quality("one_track"))
def duplicate_track(ctx: Context) -> Iterator[Hits]:
    """Two participants' reference points stay closer than min(``duplicate_distance_m``, half the
    narrower width) for at least ``duplicate_share`` of their common frames and at least
    ``duplicate_min_s``: a duplicated track (two detections of one object, or a copy)."""
    p = _pairs(ctx)
    if p is None:
        return
    dups = _duplicates(ctx, p)
    if not len(dups):
        return
    S = ctx.collected["interactions.samples"]
    mask = p["close"] & np.isin(p["key"], dups)
    yield _pair_hits(S, p, mask, p["dist"], "distance")
