"""Interactions between participants: overlapping footprints and duplicated tracks.

Both rules share one vectorised pass (cached in ``ctx.cache``): samples are put on the frame grid of
``nominal_rate_hz`` (positions moved to the frame time with their velocity), hashed into grid cells
as large as the largest footprint, and every pair of samples in the same or a neighbouring cell of
the same frame is a candidate; oriented footprints are then tested with the separating-axis theorem.
No Python loop runs over samples or pairs.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pyarrow as pa

from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hits, rule
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
    f = frame - frame.min()
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


def _pairs(ctx: Context):
    """Pair statistics shared by the interaction rules (cached)."""
    if "interactions.pairs" in ctx.cache:
        return ctx.cache["interactions.pairs"]
    ctx.cache["interactions.pairs"] = res = _compute_pairs(ctx)
    return res


def _compute_pairs(ctx: Context):
    sv: StatesView | None = ctx.states_view
    pv = ctx.participants_view
    if sv is None or ctx.meta is None or pv.length is None or pv.width is None:
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
    if len(idx) < 2:
        return None
    cell = float(np.nanmax(diag[idx]))
    a, b = candidate_pairs(frame[idx], xf[idx], yf[idx], cell)
    a, b = idx[a], idx[b]
    keep = sv.pid[a] != sv.pid[b]
    a, b = a[keep], b[keep]
    # order each pair by participant id
    swap = sv.pid[a] > sv.pid[b]
    a, b = np.where(swap, b, a), np.where(swap, a, b)
    dx, dy = xf[b] - xf[a], yf[b] - yf[a]
    dist = np.hypot(dx, dy)
    near = dist < 0.5 * (diag[a] + diag[b])
    a, b, dx, dy, dist = a[near], b[near], dx[near], dy[near], dist[near]
    # separating-axis test of the two oriented footprints, shrunk by the tolerance
    shrink = ctx.config.interactions.overlap_depth_m
    hl_a = np.maximum(L[a] / 2 - shrink, 0.01)
    hw_a = np.maximum(W[a] / 2 - shrink, 0.01)
    hl_b = np.maximum(L[b] / 2 - shrink, 0.01)
    hw_b = np.maximum(W[b] / 2 - shrink, 0.01)
    ua = np.stack([np.cos(h[a]), np.sin(h[a])])
    na = np.stack([-np.sin(h[a]), np.cos(h[a])])
    ub = np.stack([np.cos(h[b]), np.sin(h[b])])
    nb = np.stack([-np.sin(h[b]), np.cos(h[b])])
    d = np.stack([dx, dy])
    depth = np.full(len(a), np.inf)
    for k in (ua, na, ub, nb):
        ra = hl_a * np.abs((ua * k).sum(0)) + hw_a * np.abs((na * k).sum(0))
        rb = hl_b * np.abs((ub * k).sum(0)) + hw_b * np.abs((nb * k).sum(0))
        depth = np.minimum(depth, ra + rb - np.abs((d * k).sum(0)))
    overlap = depth > 0
    # exclusions: attached participants
    att = num(pv.table, "attached_to", "participants")
    excluded = np.zeros(len(a), bool)
    if att is not None:
        aa = np.where(sv.pidx[a] >= 0, att[np.maximum(sv.pidx[a], 0)], np.nan)
        ab = np.where(sv.pidx[b] >= 0, att[np.maximum(sv.pidx[b], 0)], np.nan)
        excluded |= (aa == sv.pid[b]) | (ab == sv.pid[a])
    excluded |= in_accident(ctx, sv.pid[a], sv.pid[b], sv.t[a])
    # duplicate tracks: close for most of the common time
    ic = ctx.config.interactions
    close_d = np.minimum(ic.duplicate_distance_m, 0.5 * np.minimum(W[a], W[b]))
    close = dist < close_d
    pair_key = sv.seg[a].astype(np.int64) * len(sv.starts) + sv.seg[b]
    return {"a": a, "b": b, "depth": depth, "overlap": overlap & ~excluded, "close": close,
            "key": pair_key, "rate": rate, "frame": frame, "x": xf, "y": yf,
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
    sv = ctx.states_view
    ic = ctx.config.interactions
    keys = p["key"][p["close"]]
    dup = np.zeros(0, np.int64)
    if len(keys):
        u, cnt = np.unique(keys, return_counts=True)
        # common frames of each pair: overlap of the two participants' frame ranges
        fr = p["frame"]
        first = fr[sv.starts]
        last = fr[sv.ends - 1]
        sa, sb = u // len(sv.starts), u % len(sv.starts)
        common = np.minimum(last[sa], last[sb]) - np.maximum(first[sa], first[sb]) + 1
        ok = (cnt >= ic.duplicate_share * np.maximum(common, 1)) & (cnt / p["rate"] >= ic.duplicate_min_s)
        dup = u[ok]
    ctx.cache["interactions.dups"] = dup
    return dup


def _per_pair(sv: StatesView, p, mask: np.ndarray, value: np.ndarray):
    a, b, key = p["a"][mask], p["b"][mask], p["key"][mask]
    val = value[mask]
    order = np.lexsort((sv.t[a], key))
    a, b, key, val = a[order], b[order], key[order], val[order]
    first = np.r_[0, np.flatnonzero(np.diff(key)) + 1]
    counts = np.diff(np.r_[first, len(key)])
    peak = np.maximum.reduceat(val, first) if len(val) else val
    i, j = a[first], b[first]
    o = np.argsort(sv.row[i], kind="stable")
    return i[o], j[o], counts[o], peak[o]


@rule("interactions.overlap", "warning", "Footprints of two participants overlap",
      "states.parquet: row {row}: participant {participant_id} and {other_id} overlap by {value} m "
      "at {time} s ({n_frames} frames): a tracking error unless it was an accident")
def overlap(ctx: Context) -> Iterator[Hits]:
    """The footprints (length x width around the reference point, oriented by heading, shrunk by
    ``[interactions] overlap_depth_m``) of two participants overlap at the same time. Exempt: a
    participant ``attached_to`` the other, times covered by an ``accident`` event naming both, and
    pairs reported by interactions.duplicate_track. One finding per pair."""
    p = _pairs(ctx)
    if p is None:
        return
    sv = ctx.states_view
    mask = p["overlap"] & ~np.isin(p["key"], _duplicates(ctx, p))
    if not mask.any():
        return
    i, j, counts, peak = _per_pair(sv, p, mask, p["depth"])
    yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                     "other_id": sv.pid[j], "time": sv.t[i],
                                     "x": np.round(p["x"][i], 2), "y": np.round(p["y"][i], 2),
                                     "value": np.round(peak, 3), "n_frames": counts},
               const={"file": "states.parquet", "table": "states", "column": "x,y"})


@rule("interactions.duplicate_track", "warning", "One object tracked twice",
      "states.parquet: row {row}: participants {participant_id} and {other_id} move together "
      "(centres within {distance} m in {n_frames} frames of their common time): one object "
      "tracked twice")
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
    sv = ctx.states_view
    mask = p["close"] & np.isin(p["key"], dups)
    dist = np.hypot(p["x"][p["b"]] - p["x"][p["a"]], p["y"][p["b"]] - p["y"][p["a"]])
    i, j, counts, peak = _per_pair(sv, p, mask, dist)
    yield Hits(total=len(i), arrays={"row": sv.row[i], "participant_id": sv.pid[i],
                                     "other_id": sv.pid[j], "time": sv.t[i],
                                     "x": np.round(p["x"][i], 2), "y": np.round(p["y"][i], 2),
                                     "distance": np.round(peak, 3), "n_frames": counts},
               const={"file": "states.parquet", "table": "states", "column": "x,y"})
