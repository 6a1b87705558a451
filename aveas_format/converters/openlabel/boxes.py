"""The boxes of an OpenLABEL import, from the decoded blocks to the states' columns.

:class:`Boxes` takes the blocks of :func:`~.decode.decode_block` in file order: per frame its key,
timestamp, transforms and objects; each box's columns go into a
:class:`~aveas_format.io.resort.StatesWriter` (keyed by the box's object: in memory, or spilled in
bounded memory) and a few numbers of it stay here (its object, frame, root coordinate system and
flags). :meth:`Boxes.decide` makes, once every frame is read, what the import decides over all
boxes (:class:`Plan`): the frames' order (a key given twice: the last frame, as ``json.loads``
reads it) and times, the objects imported and their participant ids, the boxes dropped (objects
that are no road users, objects without any cuboid: no 3D state, sentinel sizes, states that repeat a participant and time: the first in
frame order is kept), whether velocities, accelerations and road coordinates come from the file,
the world CRS. :func:`states_of` turns a bucket of whole participants' boxes into states columns.
"""

from __future__ import annotations

from decimal import Decimal

import math
from collections import defaultdict
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.common.assemble import group_median
from aveas_format.converters.common.geometry import rotate, rotated_std
from aveas_format.converters.common.timestamps import resolve_timestamps, timestamp_value, to_utc
from aveas_format.converters.labels import LabelFilter, implausible_size
from aveas_format.converters.openlabel.findings import jpath, report_bad_sizes, report_no_state, report_repeats
from aveas_format.converters.common.coordinate_systems import utm_crs
from aveas_format.converters.openlabel.geometry import in_intervals, place, static_cuboids
from aveas_format.converters.openlabel.profile import (EXT, FRAME_ATTRIBUTES, LIGHTS, VELOCITY_ATTRIBUTES,
                                                       attributes_of, first_value, object_type)
from aveas_format.errors import FormatError, report_source
from aveas_format.io.resort import StatesWriter
from aveas_format.parallel import background
from aveas_format.schema.tables import TABLES

_HV, _HACC, _HR, _BAD, _CTS = 1, 2, 4, 8, 16
#: a box's columns besides its extension's: placed (:func:`~.geometry.place`) and its attributes
_ROWS = ("px", "py", "pz", "yaw", "dl", "dw", "dh",
         *(c for shape, cols in FRAME_ATTRIBUTES.values() if shape == "vector" for c in cols),
         *(cols for shape, cols in FRAME_ATTRIBUTES.values() if shape in ("number", "flag")), "road_id", "lane_id")
_TYPES = {"road_id": pa.string(), "lane_id": pa.int64()}
#: the attributes' columns that are states columns as they are (the road's: when the file's are used)
_DIRECT = {c for c in _ROWS[7:] if c in TABLES["states"]} - {"road_s", "road_t", "road_id", "lane_id"}


class Boxes:
    """The frames and boxes of one import, block by block (module docstring); ``spill_dir`` and
    ``memory``: the :class:`~aveas_format.io.resort.StatesWriter`'s."""

    def __init__(self, path: Path | None, spill_dir: Path | None = None, memory: int | None = None) -> None:
        self.path = path
        self.writer = StatesWriter(spill_dir, memory=memory, key="uidx")
        self.keys: list = []
        self.stamps: list = []
        self.props: dict[int, dict] = {}
        self.uid_index: dict[str, int] = {}
        #: per frame occurrence its objects' indices (flat, in parts) and how many each has
        self.slots: list[np.ndarray] = []
        self.frame_len: list[np.ndarray] = []
        self.parts: dict[str, list[np.ndarray]] = defaultdict(list)  # per box: uidx, occ, root, flags
        self.cts: list = []  # per block its boxes' own timestamps (a number: as many NaN)
        self.root_names: dict[str | None, int] = {None: 0}
        self.n = 0
        self.types: dict[str, str] = {}
        #: per object its boxes' text attribute ``type`` (a generic label's subtype)
        self.subtypes: dict[str, str] = {}
        #: per object the label kinds without a 3D state it has in a frame (bbox, poly2d...)
        self.shapes: dict[str, set[str]] = {}
        self.found: dict[tuple[str, str], list] = {}
        self.interior: list[tuple[int, str, dict]] = []
        self.nonsimple = False

    def found_at(self, code: str, what: str, frame: Any, uid: str | None, count: int) -> None:
        f = self.found.get((code, what))
        if f is None:
            self.found[(code, what)] = [frame, uid, count]
        else:
            f[2] += count

    def add(self, b) -> None:
        """A decoded block (:class:`~.decode.Block`)."""
        j0 = len(self.keys)
        self.keys += b.keys
        self.stamps += map(timestamp_value, b.stamps)
        self.props.update((j0 + j, p) for j, p in b.props.items())
        ui = self.uid_index
        for u in b.uids:
            if u not in ui:
                ui[u] = len(ui)
        idx = np.fromiter(map(ui.__getitem__, b.uids), np.int32, len(b.uids))
        self.slots.append(idx)
        self.frame_len.append(b.frame_len)
        for u, t in b.types.items():
            self.types.setdefault(u, t)
        for u, t in b.subtypes.items():
            self.subtypes.setdefault(u, t)
        for u, kinds in b.shapes.items():
            self.shapes.setdefault(u, set()).update(kinds)
        slot = b.cols["slot"]
        occ = (j0 + b.frame_of_slot[slot]).astype(np.int32)
        for code, what, i, count in b.found:
            self.found_at(code, what, self.keys[occ[i]], b.uids[slot[i]], count)
        for s, irow in b.interior:
            self.interior.append((j0 + int(b.frame_of_slot[s]), b.uids[s], irow))
        self._rows(b.cols, idx[slot], occ, b.ext)

    def _rows(self, c: dict[str, np.ndarray], uidx: np.ndarray, occ: np.ndarray, ext: dict) -> None:
        n = len(uidx)
        if not n:
            return
        rn = self.root_names
        root = np.zeros(n, np.int32)
        if c["csroot"].any():
            self.nonsimple = True
            root = np.fromiter((rn.setdefault(r, len(rn)) for r in c["csroot"].tolist()), np.int32, n)
        cts = np.isfinite(c["cub_ts"])
        flags = (c["hv"] * _HV | c["hacc"] * _HACC | c["hr"] * _HR | c["bad"] * _BAD | cts * _CTS).astype(np.uint8)
        self.cts.append(c["cub_ts"] if cts.any() else n)
        for k, a in (("uidx", uidx), ("occ", occ), ("root", root), ("flags", flags)):
            self.parts[k].append(a)
        cols = {"box": np.arange(self.n, self.n + n, dtype=np.int64), "uidx": uidx, "occ": occ}
        self.n += n
        for k in _ROWS:
            cols[k] = pa.array(c[k], _TYPES.get(k), from_pandas=c[k].dtype == object)
        for m, (vals, present) in ext.items():
            cols[f"ext:{m}"], cols[f"has:{m}"] = vals, present
        self.writer.add(cols)

    def add_static(self, objects: Any, systems) -> None:
        """The boxes of objects whose static cuboid lies in a coordinate system that a frame's
        transforms move (KITTI's ego car in ``vehicle-iso8855``, moved by the odometry): one box
        per such frame within the object's frame intervals, where the frame has none of it; the
        object counts as the frame's last."""
        statics = static_cuboids(objects)
        if not statics or not self.props:
            return
        occ_all, uidx_all = (np.concatenate(self.parts[k] or [np.zeros(0, np.int32)]) for k in ("occ", "uidx"))
        rows = []
        for j in sorted(self.props):
            edges = self.props[j].get("_edges") or systems.frame_edges(self.props[j].get("transforms"))
            boxed = set(uidx_all[occ_all == j].tolist())
            for u, cub, intervals in statics:
                if self.uid_index.get(u) not in boxed and in_intervals(self.keys[j], intervals) \
                        and systems.resolve(cub.get("coordinate_system"), edges)[2]:
                    rows.append((j, u, cub, edges))
        if not rows:
            return
        n = len(rows)
        v, nval = np.full((n, 10), np.nan), np.zeros(n, np.int8)
        for i, (_, u, cub, _) in enumerate(rows):
            try:
                vals = [float(a) for a in cub["val"]]
            except (TypeError, ValueError):
                raise FormatError(f"object {u}: static cuboid val holds non-numbers: {str(cub['val'])[:80]}",
                                  path=self.path) from None
            nval[i] = len(vals)
            v[i, :min(len(vals), 10)] = vals[:10]
        cs = np.array([cub.get("coordinate_system") for _, _, cub, _ in rows], object)
        c = place(v, nval, cs, lambda i: systems.resolve(cs[i], rows[i][3]),
                  lambda i: f"object {rows[i][1]} in frame {self.keys[rows[i][0]]}")
        c.update(hv=np.zeros(n, bool), hacc=np.zeros(n, bool), hr=np.zeros(n, bool), cub_ts=np.full(n, np.nan),
                 bad=implausible_size(np.column_stack([c["dl"], c["dw"], c["dh"]])))  # (n > 0 here)
        for k in _ROWS:
            c.setdefault(k, np.full(n, None, object) if k in _TYPES else np.full(n, np.nan))
        uidx = np.array([self.uid_index.setdefault(u, len(self.uid_index)) for _, u, _, _ in rows], np.int32)
        self.extra = (np.array([j for j, _, _, _ in rows], np.int64), uidx)
        self._rows(c, uidx, self.extra[0].astype(np.int32), {})

    # ---- once every frame is read ---------------------------------------------------------
    def decide(self, ol: dict[str, Any], options, keep_objects) -> Plan:
        """What the import decides over all boxes (:class:`Plan`); ``keep_objects(uids, types)``:
        which objects are imported by their type (None: all), ``(keep, report)``."""
        ext = _extension_of(ol)
        objects = ol.get("objects") or {}
        last: dict = {}
        for j, k in enumerate(self.keys):
            last[k] = j
        fkeys = sorted(last, key=lambda k: (int(k) if str(k).lstrip("-").isdigit() else 0, str(k)))
        rank_of = np.full(len(self.keys), -1, np.int64)
        rank_of[[last[k] for k in fkeys]] = np.arange(len(fkeys))
        fnum, time_of, start_time, resolved = frame_times(fkeys, {k: self.stamps[last[k]] for k in fkeys},
                                                          ext, ol.get("metadata") or {}, options, self.path)
        time_of_occ = np.full(len(self.keys), np.nan)
        time_of_occ[[last[k] for k in fkeys]] = [time_of[k] for k in fkeys]
        names = list(self.uid_index)
        seen = [names[i] for i in self._first_seen(rank_of) if names[i] not in objects]
        uids = [*objects, *seen]
        uidx, occ, root, flags = (np.concatenate(self.parts[k]) if self.parts[k] else np.zeros(0, np.int32)
                                  for k in ("uidx", "occ", "root", "flags"))
        frame_kept = rank_of[occ] >= 0 if len(occ) else np.zeros(0, bool)
        p = Plan(fkeys=fkeys, fnum=fnum, time_of=time_of, start_time=start_time, resolved=resolved,
                 ext=ext, objects=objects, names=names, rank_of=rank_of)
        # the objects imported (by type; and, in foreign files, not left without a plausible box)
        by_type = keep_objects(uids, self.types) if ext is None else None
        keep_idx = np.ones(len(names), bool)
        if by_type is not None:
            keep, report = by_type
            keep_idx = np.asarray([keep.get(u, True) for u in names], bool)
            typed = frame_kept & keep_idx[uidx]
            bad = typed & (flags & _BAD > 0)
            ok = typed & ~bad
            report()
            if bad.any():
                first = int(np.flatnonzero(bad)[np.argmin(rank_of[occ[bad]])])
                report_bad_sizes(int(bad.sum()), {names[i] for i in np.unique(uidx[bad]).tolist()},
                                 self.keys[occ[first]], names[uidx[first]], self.path)
            left = np.zeros(len(names), bool)
            left[uidx[ok]] = True
            had = np.zeros(len(names), bool)
            had[uidx[typed]] = True
            # an object without any box has no 3D state (2D labels only...): not a participant
            p.no_state = [u for u in uids if keep.get(u, True) and (u not in self.uid_index
                                                                    or not had[self.uid_index[u]])]
            keep_idx &= left
            kept = ok & keep_idx[uidx]
            uids = [u for u in uids if keep.get(u, True) and u in self.uid_index and keep_idx[self.uid_index[u]]]
        else:
            kept = frame_kept.copy()
            p.no_state = []
        p.uids, p.keep_idx = uids, keep_idx
        p.obj_ext, p.pid_of = participant_ids(objects, uids)
        p.pid_of_idx = np.asarray([p.pid_of.get(u, -1) for u in names], np.int64)
        p.sized = frame_kept & keep_idx[uidx] & (flags & _BAD == 0 if by_type is not None else True)
        p.has_vel = bool((flags[frame_kept] & _HV > 0).all())
        p.has_road = bool((flags[frame_kept] & _HR > 0).any())
        # the boxes' times: their frame's, or their own where every box kept has one (absolute)
        p.time = time_of_occ[occ] if len(occ) else np.zeros(0)
        if ext is None and kept.any() and (flags[kept] & _CTS > 0).all():
            cts = np.concatenate([np.full(c, np.nan) if isinstance(c, int) else c for c in self.cts])
            ts = resolve_timestamps(cts[kept].tolist(), options.timestamp_unit, what="cuboid attribute timestamp")
            if ts.epoch:
                p.time = np.full(len(occ), np.nan)
                p.time[kept] = ts.seconds
                p.resolved.update(ts.resolved())
                if not options.start_time:
                    p.start_time = ts.start_time
        # one state per participant and time: the first in frame order
        idx = np.flatnonzero(kept)
        pid, t = p.pid_of_idx[uidx[idx]], p.time[idx]
        order = np.lexsort((idx, rank_of[occ[idx]], t, pid))
        rep = np.zeros(len(idx), bool)
        rep[order[1:]] = (pid[order][1:] == pid[order][:-1]) & (t[order][1:] == t[order][:-1])
        if rep.any():
            first = idx[rep][np.argmin(rank_of[occ[idx[rep]]] * (self.n + 1) + idx[rep])]
            report_repeats(int(rep.sum()), self.keys[occ[first]], names[uidx[first]], self.path)
            kept[idx[rep]] = False
        p.final = kept
        p.n = int(kept.sum())
        if p.n:  # (none: the import's error says what the objects have)
            report_no_state(p.no_state, objects, self.shapes, self.path)
        p.has_acc = bool((flags[kept] & _HACC > 0).all())
        roots = {r for r, c in self.root_names.items() if r and (root[kept] == c).any()}
        p.wcrs = options.world_crs
        if p.wcrs is None and len(roots) == 1:
            r = next(iter(roots))
            p.wcrs = utm_crs(r)
        p.interior = self._interior(rank_of, p)
        return p

    def _first_seen(self, rank_of: np.ndarray) -> list[int]:
        """The objects of the frames kept in order of their first appearance in frame key order
        (then in the frame's order; a moving static object last in its frame)."""
        if not self.slots:
            return []
        slot = np.concatenate(self.slots)
        flen = np.concatenate(self.frame_len).astype(np.int64)
        frame = np.repeat(np.arange(len(flen)), flen)
        place_in = np.arange(len(slot)) - np.repeat(np.cumsum(flen) - flen, flen)
        width = int(flen.max(initial=0)) + 2
        key = rank_of[frame] * width + place_in
        kept = rank_of[frame] >= 0
        slot, key = slot[kept], key[kept]
        extra = getattr(self, "extra", None)
        if extra is not None and (rank_of[extra[0]] >= 0).any():
            ok = rank_of[extra[0]] >= 0
            slot = np.r_[slot, extra[1][ok]]
            key = np.r_[key, rank_of[extra[0][ok]] * width + width - 1]
        first = np.full(len(self.uid_index), np.iinfo(np.int64).max)
        np.minimum.at(first, slot, key)
        order = np.argsort(first, kind="stable")
        return order[first[order] < np.iinfo(np.int64).max].tolist()

    def _interior(self, rank_of: np.ndarray, p: Plan) -> dict[str, list]:
        out: dict[str, list] = defaultdict(list)
        for r, i in sorted((int(rank_of[j]), i) for i, (j, _, _) in enumerate(self.interior) if rank_of[j] >= 0):
            _, u, irow = self.interior[i]
            if u in p.pid_of:
                out["participant_id"].append(p.pid_of[u])
                out["time"].append(p.time_of[p.fkeys[r]])
                for c in ("automation_longitudinal_p", "automation_lateral_p", "steering_angle",
                          "steering_angle_std", "brake_pedal", "accelerator_pedal", "gear"):
                    out[c].append(irow.get(c))
        return out

    def close(self) -> None:
        self.writer.close()


class Plan(SimpleNamespace):
    """What :meth:`Boxes.decide` decided (per box arrays are indexed by the box's number)."""


def _extension_of(ol: dict[str, Any]) -> dict[str, Any] | None:
    md = ol.get("metadata") or {}
    return md.get(EXT) if isinstance(md.get(EXT), dict) else None


def frame_times(fkeys: list, stamps: dict[Any, Any], ext: dict[str, Any] | None, md: dict[str, Any],
                options, path: Path | None = None) -> tuple[dict, dict, str, dict[str, str]]:
    """``(frame number by key, time by key, start_time, resolved)``: in our own files the frames'
    timestamps are seconds since ``acquisition_date``; in foreign files their unit and epoch are
    inferred (:func:`~aveas_format.converters.common.resolve_timestamps`; ``timestamp_unit``
    fixes the unit); without a timestamp on every frame, frame numbers at ``rate_hz``.
    ``resolved`` records the choice for the ``source`` block."""
    fnum = {k: (int(k) if str(k).lstrip("-").isdigit() else i) for i, k in enumerate(fkeys)}
    start_time = None
    resolved: dict[str, str] = {}
    if ext and ext.get("start_time"):
        start_time = ext["start_time"]
        time_of = {k: float(stamps[k]) if isinstance(stamps[k], (int, float, Decimal)) else 0.0 for k in fkeys}
    else:
        ts = resolve_timestamps([stamps[k] for k in fkeys], options.timestamp_unit,
                                what="frame_properties.timestamp") if fkeys else None
        if ts is not None and np.isfinite(ts.seconds).all():
            time_of = dict(zip(fkeys, ts.seconds.tolist()))
            start_time = ts.start_time
            resolved = ts.resolved()
        else:
            f0 = min(fnum.values()) if fnum else 0
            time_of = {k: (fnum[k] - f0) / options.rate_hz for k in fkeys}
            missing = "no frame has" if ts is None or np.isnan(ts.seconds).all() else "not every frame has"
            resolved = {"timestamps": f"{missing} a timestamp: frame numbers at rate_hz {options.rate_hz:g}"}
        if start_time is None and md.get("acquisition_date"):
            try:
                start_time = to_utc(str(md["acquisition_date"]))
            except FormatError:
                report_source("source.openlabel.bad_metadata", f"metadata.acquisition_date "
                              f"{md['acquisition_date']!r} is not an ISO 8601 time: ignored", stacklevel=3,
                              file=str(path) if path is not None else None,
                              json_path="$.openlabel.metadata.acquisition_date")
    start_time = options.start_time or start_time or "1970-01-01T00:00:00Z"
    return fnum, time_of, start_time, resolved


def participant_ids(objects: dict[str, Any], uids: list[str]) -> tuple[dict, dict[str, int]]:
    """``(extension item by object, participant id by object)``: the ids our own export wrote, else
    the object keys where all are numbers, else 0, 1, ... in order."""
    obj_ext = {}
    for u in uids:
        size_items = attributes_of((objects.get(u) or {}).get("object_data")).get("dimensions/size") or []
        e = size_items[0].get(EXT) if size_items and isinstance(size_items[0].get(EXT), dict) else None
        obj_ext[u] = e
    if all(e is not None and "participant_id" in e for e in obj_ext.values()) and uids:
        pid_of = {u: int(obj_ext[u]["participant_id"]) for u in uids}
    elif all(str(u).isdigit() for u in uids):
        pid_of = {u: int(u) for u in uids}
    else:
        pid_of = {u: i for i, u in enumerate(uids)}
    return obj_ext, pid_of


# ================================================================================================
# a bucket of boxes -> states columns
# ================================================================================================

def states_of(t: pa.Table, p: Plan, ctx) -> tuple[pa.Table, dict[int, np.ndarray]]:
    """The states columns of the boxes ``t`` (whole participants) that the plan keeps, and the
    median size of each of their objects without a static size (by object index)."""
    box = t.column("box").to_numpy()
    uidx = t.column("uidx").to_numpy()
    sizes = _sizes(t, p.sized[box], uidx, ctx.needs_size)
    keep = np.flatnonzero(p.final[box])
    if len(keep) < t.num_rows:
        t = t.take(pa.array(keep))
    rows = {c: _numpy(t.column(c)) if c not in _TYPES else t.column(c).combine_chunks()
            for c in t.column_names if not c.startswith(("ext:", "has:"))}
    n = len(keep)
    pid = p.pid_of_idx[rows["uidx"]]
    states: dict[str, Any] = {"participant_id": pid, "time": p.time[rows["box"]]}
    x, y, heading = _to_local(rows, ctx.local, p.wcrs)
    states.update(x=x, y=y, heading=heading, z=rows["pz"])
    if p.has_vel and n:
        states["vx"], states["vy"] = rotate(rows["vu"], rows["vv"], heading)
        if p.has_acc:
            states["ax"], states["ay"] = rotate(rows["au"], rows["av"], heading)
        su, sv = rows["vu_std"], rows["vv_std"]
        if np.isfinite(su).any():
            states["vx_std"], states["vy_std"] = rotated_std(su, sv, None, -heading)
        su, sv = rows["au_std"], rows["av_std"]
        if np.isfinite(su).any() and "ax" in states:
            states["ax_std"], states["ay_std"] = rotated_std(su, sv, None, -heading)
    for name, (shape, cols) in FRAME_ATTRIBUTES.items():  # the attributes that are states columns
        for c in (cols if shape == "vector" else [cols]):
            if c in _DIRECT and (p.has_vel or name not in VELOCITY_ATTRIBUTES) and np.isfinite(rows[c]).any():
                states[c] = pa.array(rows[c], mask=np.isnan(rows[c]), type=pa.float32()) if c in LIGHTS \
                    else rows[c]
    ext = {c[4:]: (t.column(c), _numpy(t.column("has:" + c[4:]))) for c in t.column_names if c.startswith("ext:")}
    # lon/lat of the local positions (PROJ, without the GIL) while the rest is put together
    lonlat = background(ctx.local.to_wgs84, x, y) if n and not {"x", "y", "lon", "lat"} & ext.keys() else None
    if ctx.use_file and n:
        _file_road_coordinates(states, rows, ctx.net, ext.get("lane_offset"))
    _apply_extension(states, ext)
    states = _arrays(states, p.ext)
    if lonlat is not None:
        lon, lat = lonlat.result()
        states["lon"], states["lat"] = pa.array(lon), pa.array(lat)
    return pa.table(states), sizes


def _numpy(col) -> np.ndarray:
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if pa.types.is_floating(col.type):
        return col.fill_null(np.nan).to_numpy(zero_copy_only=False) if col.null_count else \
            col.to_numpy(zero_copy_only=False)
    if pa.types.is_boolean(col.type):
        return col.fill_null(False).to_numpy(zero_copy_only=False)
    if pa.types.is_integer(col.type) and not col.null_count:
        return col.to_numpy(zero_copy_only=False)
    return np.asarray(col.to_pylist(), object) if len(col) else np.zeros(0, object)


def _sizes(t: pa.Table, sized: np.ndarray, uidx: np.ndarray, needs_size) -> dict[int, np.ndarray]:
    """Per object without a static size the median (length, width, height) of its boxes (NaN
    where one of them has NaN: a height the file leaves out)."""
    sel = np.flatnonzero(sized & needs_size[uidx])
    uniq, code = np.unique(uidx[sel], return_inverse=True)
    dims = []
    for c in ("dl", "dw", "dh"):
        v = _numpy(t.column(c))[sel]
        dims.append(np.where(np.bincount(code, np.isnan(v), len(uniq)) > 0, np.nan,
                             group_median(code, v, len(uniq))))
    return dict(zip(uniq.tolist(), np.column_stack(dims))) if len(sel) else {}


def _to_local(rows: dict[str, np.ndarray], local, wcrs: str | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Box centres and yaw in the map's local frame: through WGS 84 where the root coordinate
    system has a CRS (``world_crs``, or a UTM root's name), else the root is the map frame."""
    from aveas_format.crs import parse_crs
    from aveas_format.numeric import wrap_angle

    px, py, yaw = rows["px"], rows["py"], rows["yaw"]
    if wcrs is not None and len(px):
        import pyproj

        tr = pyproj.Transformer.from_crs(parse_crs(wcrs).crs, "EPSG:4326", always_xy=True)
        lon, lat = tr.transform(px, py)
        lon2, lat2 = tr.transform(px + np.cos(yaw), py + np.sin(yaw))
        x, y = local.from_wgs84(np.asarray(lon), np.asarray(lat))
        x2, y2 = local.from_wgs84(np.asarray(lon2), np.asarray(lat2))
        return x, y, wrap_angle(np.arctan2(y2 - y, x2 - x))
    return px, py, wrap_angle(yaw)


def _file_road_coordinates(states: dict[str, Any], rows: dict[str, np.ndarray], net, given) -> None:
    """The file's road coordinates into ``states`` (the lane offset from ``lane_position`` and the
    lane's width in the map, except where the extension gives it: ``given``, its values and where
    it is present)."""
    n = len(rows["road_s"])
    states["road_id"] = road = rows["road_id"]
    states["lane_id"] = lanes = rows["lane_id"].cast(pa.int16())
    states["road_s"], states["road_t"] = rows["road_s"], rows["road_t"]
    lp = rows["lane_position"]
    if not np.isfinite(lp).any():
        return
    known = pc.is_in(road, value_set=pa.array(net.road_ids, pa.string())).fill_null(False)
    ok = np.isfinite(lp) & known.to_numpy(zero_copy_only=False)  # (a road the map lacks: no offset)
    if given is not None and pa.types.is_floating(given[0].type):
        ok &= ~given[1]  # (present in the extension: null or a value, the map's is not used)
    lo = np.full(n, np.nan)
    idx = np.flatnonzero(ok)
    if len(idx):
        lane = lanes.fill_null(0).to_numpy(zero_copy_only=False).astype(np.int64)
        inner, outer = net.lane_borders(road.take(idx).to_numpy(zero_copy_only=False), states["road_s"][idx], lane[idx])
        lo[idx] = lp[idx] * np.abs(outer - inner)
    states["lane_offset"] = lo


def _apply_extension(states: dict[str, Any], ext: dict[str, tuple]) -> None:
    """The ``aveas_format`` members of this library's own export into ``states``: its columns, and
    the exact values (and nulls) where the profile's would differ."""
    for c in sorted(ext):
        vals, present = ext[c]
        if isinstance(vals, pa.ChunkedArray):
            vals = vals.combine_chunks()
        base = states.get(c)
        null = vals.is_null().to_numpy(zero_copy_only=False)
        if pa.types.is_floating(vals.type) or pa.types.is_null(vals.type):
            fv = vals.cast(pa.float64()).fill_null(np.nan).to_numpy(zero_copy_only=False)
            if base is None and (present & ~null).any():
                states[c] = pa.array(fv, mask=~(present & ~null), type=pa.float64())
                continue
            if isinstance(base, np.ndarray) and base.dtype == np.float64:
                nulls = np.where(present, null, np.isnan(base))
                if not nulls.all():
                    states[c] = pa.array(np.where(present, fv, base), mask=nulls, type=pa.float64())
                    continue
        if base is None:
            states[c] = vals  # (null where missing)
            continue
        cur = base.to_pylist() if isinstance(base, (pa.Array, pa.ChunkedArray)) else [
            None if (isinstance(b, float) and math.isnan(b)) else b for b in np.asarray(base).tolist()]
        states[c] = pa.array([v if p else b for v, p, b in zip(vals.to_pylist(), present.tolist(), cur)])


def _arrays(states: dict[str, Any], ext: dict[str, Any] | None) -> dict[str, pa.Array]:
    """The states' columns as Arrow arrays (only those our own export had, where it says)."""
    keep = (ext or {}).get("states_columns")
    return {c: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else pa.array(np.asarray(v), from_pandas=True))
            for c, v in states.items() if not keep or c in keep}


def keep_by_type(path: Path | None, objects: dict[str, Any], keep_non_road_users: bool):
    """``keep_objects`` of :meth:`Boxes.decide` for foreign files: ``(whether each object is
    imported by its type, a function reporting those that are not)``."""

    def decide(uids: list[str], frame_types: dict[str, str]):
        labels = LabelFilter(keep_non_road_users)
        keep: dict[str, bool] = {}
        first_skipped = None
        for u in uids:
            keep[u] = labels(object_type(objects, u, frame_types)) is not None
            if first_skipped is None and not keep[u]:
                first_skipped = u

        def report() -> None:
            note = labels.note("objects")
            if note:
                report_source("source.openlabel.skipped_object", "OpenLABEL: " + note,
                              count=sum(labels.skipped.values()), stacklevel=5,
                              file=str(path) if path is not None else None, uid=first_skipped,
                              json_path=jpath("objects", first_skipped, "type"))
        return keep, report
    return decide


def needs_size(objects: dict[str, Any], names: list[str]) -> np.ndarray:
    """Per object (``names``) whether it has no static ``dimensions/size`` (its boxes' median)."""
    def need(u: str) -> bool:
        try:
            return first_value(attributes_of((objects.get(u) or {}).get("object_data")), "dimensions/size") is None
        except Exception:  # noqa: BLE001 - a damaged object: the sizes are unused
            return True
    return np.fromiter(map(need, names), bool, len(names))
