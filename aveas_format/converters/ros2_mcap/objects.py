"""The objects of a bucket of whole tracks (:mod:`~aveas_format.converters.ros2_mcap.rows`'
columns): in the map frame (:func:`objects_in_map`), then boxes (:func:`object_boxes`: sorted, a
repeated (track, stamp) dropped, tracks that are no road user dropped, velocities and headings).
Everything here is per row or per track, so that a bucket gives what the whole recording gives
for its tracks; what is decided over all rows (validity warning, time zero, the tracks' order) is
the converter's."""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.converters.common.assemble import group_mean
from aveas_format.converters.common.boxes import Boxes, Rows
from aveas_format.converters.common.geometry import covariance_std_corr
from aveas_format.converters.ros2_mcap.frames import apply_offset, cov3, to_map, twist_to_map
from aveas_format.converters.ros2_mcap.options import Ros2McapOptions
from aveas_format.converters.ros2_mcap.rows import block, ints
from aveas_format.numeric import central_differences


def objects_in_map(b: pa.Table, ctx: Any) -> dict[str, np.ndarray]:
    """The object rows of a bucket (none of the ego's) in the map frame (positions, headings,
    velocities, covariances), frame by frame; the rows outside the transforms' time spans
    dropped (the converter warned about them). ``ctx``: the converter's decisions over all rows
    (tree, frames, options, ego)."""
    o, tree, ego = ctx.options, ctx.tree, ctx.ego
    n = b.num_rows
    t_ns = ints(b, "t_ns")
    pose = block(b, "pose")
    pcov = cov3(block(b, "pcov"))
    twist = block(b, "twist")
    tcov = cov3(block(b, "tcov"))
    kind = ints(b, "kind")
    fcodes = ints(b, "frame")
    x = np.empty(n)
    y = np.empty(n)
    z = np.empty(n)
    heading = np.empty(n)
    cov = np.empty((n, 3, 3))
    vel = np.full((n, 2), np.nan)
    vcov = np.full((n, 2, 2), np.nan)
    valid = np.ones(n, bool)
    for k in np.unique(fcodes).tolist():
        sel = np.flatnonzero(fcodes == k)
        frn = ctx.frames[k].lstrip("/") or o.map_frame
        r_f, p_f, ok, cov_f = tree.lookup(frn, t_ns[sel])
        valid[sel] = ok
        pos, hd, cv, th = to_map(r_f, p_f, cov_f, pose[sel], pcov[sel])
        x[sel], y[sel], z[sel] = pos[:, 0], pos[:, 1], pos[:, 2]
        heading[sel] = hd
        cov[sel] = cv
        # velocities: object body frame (rotate by heading) or header frame (rotate by frame yaw)
        body = kind[sel] == 0
        hdr = kind[sel] == 1
        if body.any():
            bb = sel[body]
            v, vc = twist_to_map(hd[body], twist[bb], tcov[bb], cv[body, 2, 2])
            vel[bb], vcov[bb] = v, vc
        if hdr.any():
            h = sel[hdr]
            var_th = cov_f[0][hdr, 2, 2] if cov_f is not None else np.zeros(hdr.sum())
            v, vc = twist_to_map(th[hdr], twist[h], tcov[h], var_th)
            if o.relative_velocity and ego is not None and frn != o.map_frame:
                v, vc = add_ego_motion(v, vc, t_ns[h], x[h], y[h], ego)
            vel[h], vcov[h] = v, vc
    rows = {"t_ns": t_ns, "track": ints(b, "track"), "x": x, "y": y, "z": z, "heading": heading,
            "cov": cov, "vel": vel, "vcov": vcov, "dims": block(b, "dims"), "pmf": block(b, "pmf"),
            "nru": np.asarray(b.column("nru").to_numpy(), np.float64),
            "nru_label": np.asarray(b.column("nru_label").to_pylist(), dtype=object),
            "orient": ints(b, "orient")}
    return {k: v[valid] for k, v in rows.items()}


def add_ego_motion(v: np.ndarray, vc: np.ndarray, t_ns: np.ndarray, x: np.ndarray, y: np.ndarray,
                   ego: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """Velocities relative to the moving ego -> absolute: the ego's velocity (interpolated at the
    stamps) plus ``omega x r`` about its position, its velocity covariance added."""
    tq = (t_ns - ego["t"][0]).astype(np.float64)
    te = (ego["t"] - ego["t"][0]).astype(np.float64)
    evx = np.interp(tq, te, ego["v"][:, 0])
    evy = np.interp(tq, te, ego["v"][:, 1])
    w = np.interp(tq, te, ego["yaw_rate"]) if ego["yaw_rate"] is not None else 0.0
    ex = np.interp(tq, te, ego["x"])
    ey = np.interp(tq, te, ego["y"])
    v = v + np.c_[evx - w * (y - ey), evy + w * (x - ex)]
    vc = vc + np.nan_to_num(np.stack(
        [np.interp(tq, te, ego["vcov"][:, a, b]) for a in range(2) for b in range(2)],
        -1).reshape(-1, 2, 2))
    return v, vc


def road_users(boxes: Boxes, nru: np.ndarray, nru_label: np.ndarray, o: Ros2McapOptions
               ) -> tuple[Boxes, int, Counter]:
    """The boxes without the tracks whose classification is mostly a label that is no road user
    (unless ``keep_non_road_users``), the number of tracks dropped and their labels (the converter
    warns once with the counts)."""
    if o.keep_non_road_users or not len(boxes) or not (nru > 0.5).any():
        return boxes, 0, Counter()
    skip = group_mean(boxes.pid, nru, boxes.m) > 0.5
    if not skip.any():
        return boxes, 0, Counter()
    first = boxes.first_rows()
    names = Counter(str(nru_label[i]) or "no road user" for i in first[skip])
    return boxes.drop_participants(skip), int(skip.sum()), names


def skipped_message(count: int, names: Counter) -> str:
    return (f"skipped {count} tracks: " + ", ".join(f"{c} {n}" for n, c in sorted(names.items()))
            + " (no road user); option keep_non_road_users=true imports them")


def object_boxes(rows: dict[str, np.ndarray], ctx: Any, found: dict[str, Any]) -> Boxes:
    """The objects' boxes of a bucket (sorted; a repeated (track, stamp) keeps the first; tracks
    that are no road user dropped; both counted in ``found``: ``repeats``, ``skipped``,
    ``labels``): velocities from positions where the source has none, the heading from the motion
    where it is unavailable or only known up to its sign, everything in the OpenDRIVE map's frame,
    with the per-box dimensions and class PMFs. Codes 0.. in the order of the tracks' final codes
    (``ctx.key_map``), source ids ``ctx.source_ids``."""
    from aveas_format.mapref.build import heading_from_velocity

    o = ctx.options
    final, codes = np.unique(ctx.key_map[rows["track"]], return_inverse=True)
    boxes = Boxes(codes.reshape(-1), (rows["t_ns"] - ctx.t0) / 1e9, rows["x"], rows["y"],
                  source_ids=list(ctx.source_ids[final - 1]), rows=Rows([ctx.first]),
                  duplicates="first", length=rows["dims"][:, 0], width=rows["dims"][:, 1],
                  height=rows["dims"][:, 2], class_pmf=rows["pmf"]).sort(found["repeats"])
    r = {k: rows[k][boxes.order] for k in ("heading", "cov", "vel", "vcov", "orient", "nru", "nru_label")}
    keep, skipped, labels = road_users(boxes, r["nru"], r["nru_label"], o)
    found["skipped"] += skipped
    found["labels"] += labels
    if keep is not boxes:
        sel = np.flatnonzero(np.isin(boxes.order, keep.order))
        r = {k: v[sel] for k, v in r.items()}
        boxes = keep
    codes, ts = boxes.pid, boxes.time
    # velocities where the source has none: from positions
    psx = np.sqrt(np.clip(r["cov"][:, 0, 0], 0, None))
    psy = np.sqrt(np.clip(r["cov"][:, 1, 1], 0, None))
    fvx, fvy, fvxs, fvys = central_differences(codes, ts, boxes["x"], boxes["y"], psx, psy)
    nov = np.isnan(r["vel"]).any(axis=1)
    r["vel"][nov] = np.c_[fvx, fvy][nov]
    r["vcov"][nov] = 0.0
    r["vcov"][nov, 0, 0], r["vcov"][nov, 1, 1] = fvxs[nov] ** 2, fvys[nov] ** 2
    # heading where unavailable or only known up to its sign
    hv = heading_from_velocity(codes, r["vel"][:, 0], r["vel"][:, 1])
    moving = np.hypot(r["vel"][:, 0], r["vel"][:, 1]) >= 0.5
    h = np.where(r["orient"] == 0, hv, r["heading"])
    h = np.where((r["orient"] == 1) & moving & (np.cos(h - hv) < 0), h + np.pi, h)
    r["cov"][r["orient"] == 0, 2, 2] = np.nan
    x, y, h, cxy, vx, vy, vc = apply_offset(o.frame_offset, boxes["x"], boxes["y"], h,
                                            r["cov"][:, :2, :2], r["vel"][:, 0], r["vel"][:, 1],
                                            r["vcov"])
    sx, sy, rho = covariance_std_corr(cxy)
    vsx, vsy, vrho = covariance_std_corr(vc)
    for k, v in dict(x=x, y=y, heading=h, vx=vx, vy=vy, x_std=sx, y_std=sy, xy_corr=rho,
                     heading_std=np.sqrt(r["cov"][:, 2, 2]), vx_std=vsx, vy_std=vsy,
                     vxvy_corr=vrho).items():
        boxes[k] = v
    return boxes
