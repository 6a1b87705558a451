"""Dataset-wide statistics: per-vehicle values of a metric over many recordings, streamed one
recording at a time with partial reads (for the behaviour-model fitter, docs/datasets.md)."""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from aveas_format.dataset.discovery import local_copy, map_recordings
from aveas_format.dataset.report import recording_facts
from aveas_format.errors import AveasError


def _speed(t):
    import numpy as np

    vx = t.column("vx").to_numpy(zero_copy_only=False).astype(float)
    vy = t.column("vy").to_numpy(zero_copy_only=False).astype(float)
    return np.hypot(vx, vy)


#: name -> (states columns needed, per-sample values from the states table, reducer)
METRICS: dict[str, tuple[tuple[str, ...], Callable[[Any], Any], str]] = {
    "mean_speed": (("vx", "vy"), _speed, "mean"),
    "max_speed": (("vx", "vy"), _speed, "max"),
    "min_speed": (("vx", "vy"), _speed, "min"),
    "speed_std": (("vx", "vy"), _speed, "std"),
    "observed_s": ((), lambda t: t.column("time").to_numpy(zero_copy_only=False), "span"),
    "samples": ((), lambda t: t.column("time").to_numpy(zero_copy_only=False), "count"),
    "mean_lateral_offset": (("lane_offset",), lambda t: t.column("lane_offset").to_numpy(
        zero_copy_only=False).astype(float), "mean"),
}


def _matches(facts: Mapping[str, Any], filters: Mapping[str, Any] | None) -> bool:
    for key, want in (filters or {}).items():
        have = facts.get(key)
        if callable(want):
            if not want(have):
                return False
        elif isinstance(want, (list, tuple, set, frozenset)):
            if have not in want:
                return False
        elif have != want:
            return False
    return True


def per_vehicle_task(path: str, *, metric: str, filters: Mapping[str, Any] | None = None,
                     classes: list[str] | None = None) -> dict[str, Any] | None:
    """One recording's per-participant values of ``metric`` (a task): None when the recording's
    metadata does not match ``filters``; reads only the states columns the metric needs."""
    import numpy as np

    from aveas_format.io.container import Container
    from aveas_format.io.reader import open_recording, read_meta

    cols, values_of, how = METRICS[metric]
    with local_copy(path) as local:
        with Container(local) as c:
            meta, _ = read_meta(c)
        facts = recording_facts(meta)
        if not _matches(facts, filters):
            return None
        parts = open_recording(local, tables=["participants"], verify=False,
                                  columns={"participants": ["class"]}).participants
        pids_wanted = None
        if classes:
            pc_cls = np.asarray(parts.column("class").cast("string").to_pylist(), dtype=object)
            pids_wanted = parts.column("participant_id").to_numpy()[np.isin(pc_cls, classes)]
            if not len(pids_wanted):
                return {**facts, "path": path, "participant_id": [], "class": [], "value": []}
        st = open_recording(local, tables=["states"], columns=list(cols), verify=False,
                               participants=pids_wanted).states
    pid = st.column("participant_id").to_numpy()
    v = values_of(st)
    order = np.argsort(pid, kind="stable")
    pid, v = pid[order], v[order]
    ids, start = np.unique(pid, return_index=True)
    out = []
    for seg in np.split(v, start[1:]) if len(ids) else []:
        seg = seg[np.isfinite(seg)] if seg.dtype.kind == "f" else seg
        if not len(seg):
            out.append(np.nan)
        elif how == "mean":
            out.append(float(np.mean(seg)))
        elif how == "max":
            out.append(float(np.max(seg)))
        elif how == "min":
            out.append(float(np.min(seg)))
        elif how == "std":
            out.append(float(np.std(seg)))
        elif how == "span":
            out.append(float(np.max(seg) - np.min(seg)))
        else:
            out.append(float(len(seg)))
    cls_of = dict(zip(parts.column("participant_id").to_pylist(),
                      parts.column("class").cast("string").to_pylist()))
    return {**facts, "path": path, "participant_id": ids.tolist(),
            "class": [cls_of.get(int(i)) for i in ids], "value": out}


def per_vehicle_stats(paths: Iterable[str | Path], metric: str = "mean_speed", *,
                      filters: Mapping[str, Any] | None = None,
                      classes: list[str] | None = None, workers: int | None = 1,
                      scheduler: str | None = None, progress: bool = False,
                      errors: list[dict[str, Any]] | None = None):
    """Per-vehicle values of ``metric`` over a dataset as a :class:`pyarrow.Table` (columns
    recording_id, partner, method, road_type, participant_id, class, value), streamed one
    recording at a time: each task reads only recording.json, the participants' classes and the
    states columns the metric needs.

    metric: a key of :data:`METRICS` (mean_speed, max_speed, min_speed, speed_std, observed_s,
    samples, mean_lateral_offset). filters: recording.json facts to match (partner, method,
    provenance, site, country, road_type, recording_id), each a value, a list of values or a
    predicate (a predicate must be picklable for worker processes). classes: participant classes
    to keep. A recording that fails is left out and, when ``errors`` is a list, appended to it.
    """
    import pyarrow as pa

    if metric not in METRICS:
        raise AveasError(f"unknown metric {metric!r}; known: {', '.join(METRICS)}")
    fn = functools.partial(per_vehicle_task, metric=metric, filters=dict(filters or {}),
                           classes=list(classes) if classes else None)
    cols: dict[str, list] = {k: [] for k in ("recording_id", "partner", "method", "road_type",
                                             "participant_id", "class", "value")}
    for r in map_recordings(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                            progress=progress, description=metric):
        if not r.ok:
            if errors is not None:
                errors.append({"path": r.item, "error": r.error})
            continue
        d = r.value
        if d is None:
            continue
        n = len(d["value"])
        for k in ("recording_id", "partner", "method", "road_type"):
            cols[k].extend([d[k]] * n)
        cols["participant_id"].extend(d["participant_id"])
        cols["class"].extend(d["class"])
        cols["value"].extend(d["value"])
    schema = pa.schema([("recording_id", pa.string()), ("partner", pa.string()),
                        ("method", pa.string()), ("road_type", pa.string()),
                        ("participant_id", pa.int64()), ("class", pa.string()),
                        ("value", pa.float64())])
    return pa.Table.from_pydict(cols, schema=schema)
