"""Per-vehicle car-following metrics from the derived tables: time headway, minimum TTC and the
spread of the longitudinal acceleration (the paper's outlook: "TTC, THW and acceleration
distributions" to fit the car-following parameters, e.g. W99 cc1).

Recorded and simulated data go through the same code: the simulation becomes a recording (the SUMO
FCD converter), ``derive`` computes ``kinematics`` and ``interactions`` where they are missing, and
each metric reduces the samples of one vehicle to one value:

- ``time_headway`` (s): the median net time headway to the lane leader over the samples in which
  the vehicle follows steadily (``thw <= max_thw``, speed >= ``min_speed``, ``|closing_speed| <=
  max_closing``), for vehicles that do so for at least ``min_following`` seconds. In steady
  following W99's headway is about cc1 + cc0 / v, so this is the metric for cc1.
- ``min_ttc`` (s): the smallest constant-velocity TTC to the lane leader (vehicles that close in on
  a leader with ``ttc <= max_ttc`` at least once).
- ``a_lon_std`` (m/s²): the standard deviation of the smoothed longitudinal acceleration.

Only the samples of the measurement section count: for recordings those on ``road_id`` with
``road_s`` in ``s_range`` (both optional), for simulations those on the scenario's measurement edges
(joined with the recording by SUMO id and time). Classes are the participants' ``class`` for
recordings and the SUMO vType (``attributes.sumo_type``) for simulations, like the mean speeds.
"""

from __future__ import annotations

import inspect
import json

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

#: defaults of the following-state filter and the TTC cut-off
MAX_THW_S = 4.0
MIN_SPEED_M_S = 5.0
MAX_TTC_S = 20.0
MAX_CLOSING_M_S = 1.0
MIN_FOLLOWING_S = 2.0


def ensure_derived(rec, names: tuple[str, ...] = ("kinematics", "interactions")) -> None:
    """Run the derivations in ``names`` that ``rec`` lacks (in memory; nothing is written)."""
    from aveas_format.derive import derive

    missing = [n for n in names if n not in rec.derived]
    if missing:
        params = {"interactions": {"box_2d": False}} if "interactions" in missing else {}
        derive(rec, only=missing, **params)


def participant_classes(rec, by: str = "class") -> dict[int, str]:
    """participant_id -> class name: the ``class`` column, or ``attributes.sumo_type``."""
    parts = rec.participants
    ids = parts["participant_id"].to_pylist()
    if by == "class":
        return dict(zip(ids, parts["class"].cast(pa.string()).to_pylist(), strict=True))
    out = {}
    for pid, a in zip(ids, parts["attributes"].to_pylist(), strict=True):
        t = json.loads(a).get(by) if a else None
        if t is not None:
            out[pid] = str(t)
    return out


def section_states(st: pa.Table, road_id: str | None = None,
                   s_range: tuple[float, float] | None = None) -> pa.Table:
    """The states rows on ``road_id`` with ``road_s`` in ``s_range`` (either may be None)."""
    mask = None
    if road_id is not None and "road_id" in st.column_names:
        mask = pc.equal(st["road_id"].cast(pa.string()), road_id)
    if s_range is not None and "road_s" in st.column_names:
        m2 = pc.and_(pc.greater_equal(st["road_s"], s_range[0]), pc.less_equal(st["road_s"], s_range[1]))
        mask = m2 if mask is None else pc.and_(mask, m2)
    return st if mask is None else st.filter(pc.fill_null(mask, False))


def recorded_section(rec, road_id: str | None = None, s_range: tuple[float, float] | None = None
                     ) -> pa.Table:
    """(participant_id, time) of the states on ``road_id`` with ``road_s`` in ``s_range``."""
    return section_states(rec.states, road_id, s_range).select(["participant_id", "time"])


def simulated_section(res) -> pa.Table:
    """(participant_id, time) of the simulated recording's states on the measurement section."""
    fcd = res.fcd
    net = res.net
    mask = pc.is_valid(fcd["id"])
    if net.measure_edges is not None:
        mask = pc.and_(mask, pc.is_in(fcd["edge"], pa.array(net.measure_edges)))
    if net.measure_pos is not None:
        lo, hi = net.measure_pos
        mask = pc.and_(mask, pc.and_(pc.greater_equal(fcd["pos"], lo), pc.less_equal(fcd["pos"], hi)))
    inside = fcd.filter(mask).select(["id", "time"]).rename_columns(["source_id", "time"])
    rec = res.recording
    parts = rec.participants.select(["participant_id", "source_id"])
    keys = rec.states.select(["participant_id", "time"]).join(parts, "participant_id")
    inside = inside.cast(pa.schema([("source_id", pa.string()), ("time", pa.float64())]))
    keys = keys.cast(pa.schema([("participant_id", pa.int64()), ("time", pa.float64()),
                                ("source_id", pa.string())]))
    return keys.join(inside, ["source_id", "time"], join_type="inner").select(["participant_id", "time"])


def _float_time(table: pa.Table) -> pa.Table:
    return table.cast(table.schema.set(table.schema.get_field_index("time"), pa.field("time", pa.float64())))


def _in_section(table: pa.Table, section: pa.Table) -> pa.Table:
    """The rows of ``table`` whose (participant_id, time) is in ``section`` (an inner join that
    adds ``section``'s other columns)."""
    return _float_time(table).join(_float_time(section), ["participant_id", "time"], join_type="inner")


def sampling_step(rec) -> float:
    """The median time step between consecutive samples of one participant (1 s if unknown)."""
    pid = rec.states["participant_id"].to_numpy()
    t = rec.states["time"].to_numpy(zero_copy_only=False).astype(np.float64)
    same = pid[1:] == pid[:-1]
    dt = np.diff(t)[same]
    dt = dt[dt > 0]
    return float(np.median(dt)) if len(dt) else 1.0


def per_vehicle(pid: np.ndarray, v: np.ndarray, how: str, min_samples: int = 1
                ) -> tuple[np.ndarray, np.ndarray]:
    """One value per participant (``median``, ``min`` or ``std``) where it has >= ``min_samples``."""
    if len(pid) == 0:
        return np.empty(0, np.int64), np.empty(0)
    pid, v = np.asarray(pid), np.asarray(v, np.float64)
    o = np.lexsort((v, pid))                     # by participant, then value
    pid, v = pid[o], v[o]
    uniq, start, count = np.unique(pid, return_index=True, return_counts=True)
    if how == "median":
        out = 0.5 * (v[start + (count - 1) // 2] + v[start + count // 2])
    elif how == "min":
        out = v[start]
    elif how == "std":
        inv = np.repeat(np.arange(len(uniq)), count)
        mean = np.bincount(inv, weights=v) / count
        var = np.bincount(inv, weights=(v - mean[inv]) ** 2) / np.maximum(count - 1, 1)
        out = np.sqrt(var)
    else:
        raise ValueError(f"how={how!r}")
    ok = count >= min_samples
    return uniq[ok], out[ok]


def _by_class(uniq: np.ndarray, values: np.ndarray, classes: tuple[str, ...] | list[str],
              cls_of: dict[int, str]) -> dict[str, np.ndarray]:
    names = np.array([cls_of.get(int(p)) for p in uniq], dtype=object)
    return {c: values[names == c] for c in classes}


def metric_values(rec, name: str, section: pa.Table, classes, cls_of: dict[int, str], *,
                  max_thw: float = MAX_THW_S, min_speed: float = MIN_SPEED_M_S,
                  max_closing: float = MAX_CLOSING_M_S, max_ttc: float = MAX_TTC_S,
                  min_following: float = MIN_FOLLOWING_S) -> dict[str, np.ndarray]:
    """``{class: per-vehicle values}`` of metric ``name`` over the ``section`` samples."""
    ensure_derived(rec)
    min_samples = max(1, int(np.ceil(min_following / sampling_step(rec) - 1e-9)))
    if name == "a_lon_std":
        k = _in_section(rec.derived["kinematics"].select(["participant_id", "time", "a_lon"]), section)
        a = k["a_lon"].to_numpy(zero_copy_only=False).astype(np.float64)
        ok = np.isfinite(a)
        u, v = per_vehicle(k["participant_id"].to_numpy()[ok], a[ok], "std", max(min_samples, 2))
        return _by_class(u, v, classes, cls_of)
    it = rec.derived["interactions"]
    it = it.filter(pc.equal(it["relation"].cast(pa.string()), "leader"))
    it = _in_section(it.select(["participant_id", "time", "thw", "ttc", "closing_speed"]), section)
    if name == "time_headway":
        it = _in_section(it, rec.derived["kinematics"].select(["participant_id", "time", "speed"]))
        thw = it["thw"].to_numpy(zero_copy_only=False).astype(np.float64)
        speed = it["speed"].to_numpy(zero_copy_only=False).astype(np.float64)
        closing = it["closing_speed"].to_numpy(zero_copy_only=False).astype(np.float64)
        ok = (np.isfinite(thw) & (thw <= max_thw) & (speed >= min_speed)
              & (np.abs(np.nan_to_num(closing, nan=np.inf)) <= max_closing))
        u, v = per_vehicle(it["participant_id"].to_numpy()[ok], thw[ok], "median", min_samples)
    elif name == "min_ttc":
        ttc = it["ttc"].to_numpy(zero_copy_only=False).astype(np.float64)
        ok = np.isfinite(ttc) & (ttc > 0) & (ttc <= max_ttc)
        u, v = per_vehicle(it["participant_id"].to_numpy()[ok], ttc[ok], "min", 1)
    else:
        raise ValueError(f"unknown metric {name!r}")
    return _by_class(u, v, classes, cls_of)


#: the keyword options of :func:`metric_values` (thresholds of the metrics; CLI ``--option``)
METRIC_OPTIONS: tuple[str, ...] = tuple(
    n for n, prm in inspect.signature(metric_values).parameters.items() if prm.kind is prm.KEYWORD_ONLY)


def recorded_metric(name: str):
    """The ``recorded`` side of metric ``name`` (see :class:`~aveas_format.fit.objective.Metric`)."""

    def recorded(rec, *, classes: tuple[str, ...] = ("car", "truck"), road_id: str | None = None,
                 s_range: tuple[float, float] | None = None, **options) -> dict[str, np.ndarray]:
        return metric_values(rec, name, recorded_section(rec, road_id, s_range), classes,
                             participant_classes(rec), **options)

    recorded.__name__ = f"recorded_{name}"
    return recorded


def simulated_metric(name: str):
    """The ``simulated`` side of metric ``name``: needs the run's recording."""

    def simulated(res, **options) -> dict[str, np.ndarray]:
        return metric_values(res.recording, name, simulated_section(res),
                             [c.name for c in res.scenario.classes],
                             participant_classes(res.recording, by="sumo_type"), **options)

    simulated.__name__ = f"simulated_{name}"
    return simulated
