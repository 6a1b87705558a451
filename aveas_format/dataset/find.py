"""Find the most critical situations and events across an archive and cut each out for replay.

A *situation* is one participant's most critical moment in a recording: a participant row of
``derived/criticality_summary`` (its minimum TTC with the other participant and the time, the
largest DRAC, the smallest PSD and PET, TET/TIT, CPI, each with its std). :func:`situations`
gathers them from every recording of a dataset (one small table read per recording, in parallel),
:func:`find` filters them with a condition such as ``"min_ttc < 1.5 and max_drac > 3"`` and ranks
them; :func:`cut_out` writes one situation as a small recording (the two participants over a time
window around the moment, map included) and as an OpenSCENARIO file for replay.

An *event* is a derived conflict or near miss (events.parquet): :func:`critical_events` gathers
them from every recording and :func:`rank_events` filters (``"collision_probability > 0.2"``,
on :data:`EVENT_MEASURES`) and ranks them, most likely to collide first; a row is a situation for
:func:`cut_out` too (its pair around its extreme).

>>> from aveas_format.dataset import discover
>>> from aveas_format.dataset.find import find, cut_out
>>> top = find(discover(["archive/"]), where="min_ttc < 1.5", top=20)      # doctest: +SKIP
>>> cut_out(top.slice(0, 1).to_pylist()[0], "cuts/")                        # doctest: +SKIP

The same search over the catalog (``aveas-format catalog``, one row per recording with the
recording row's measures) is a query in DuckDB or pandas; docs/datasets.md has the recipe.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from aveas_format.dataset.discovery import local_copy, map_recordings
from aveas_format.errors import AveasError
from aveas_format.parallel import TaskResult

#: the measures a situation has (summary column -> its std column, or None)
MEASURES = {"min_ttc": "min_ttc_std", "max_drac": "max_drac_std", "min_psd": "min_psd_std",
            "min_pet": "min_pet_std", "tet": "tet_std", "tit": "tit_std", "cpi": "cpi_std",
            "ttc_samples_below": None, "near_misses": None, "hard_braking": None,
            "duration_s": None}
#: ranking: the measures where smaller is more critical
SMALLER_IS_WORSE = {"min_ttc", "min_psd", "min_pet"}

#: the measures of an event (events.parquet) a condition may name
EVENT_MEASURES = ("collision_probability", "value", "duration", "time_start")

_COND = re.compile(r"^\s*([a-z_]+)\s*(<=|>=|==|!=|<|>)\s*([-+0-9.eE]+)\s*$")


def parse_where(where: str | None, measures=MEASURES) -> list[tuple[str, str, float]]:
    """``"min_ttc < 1.5 and max_drac >= 3"`` -> ``[("min_ttc", "<", 1.5), ("max_drac", ">=",
    3.0)]``; conditions on ``measures`` (:data:`MEASURES`, or :data:`EVENT_MEASURES`) joined by
    ``and``. ValueError naming the part that cannot be read."""
    if not where or not where.strip():
        return []
    out = []
    for part in re.split(r"\s+and\s+", where.strip(), flags=re.IGNORECASE):
        m = _COND.match(part)
        if not m:
            raise ValueError(f"--where: cannot read {part.strip()!r}: expected MEASURE OP NUMBER "
                             "(OP one of < <= > >= == !=), joined by 'and'")
        name, op, num = m.groups()
        if name not in measures:
            raise ValueError(f"--where: unknown measure {name!r}; known: {', '.join(measures)}")
        try:
            out.append((name, op, float(num)))
        except ValueError:
            raise ValueError(f"--where: {num!r} is not a number") from None
    return out


def _with_table(path: str, table: str, read: Callable[[Any, Any], dict[str, Any]]) -> dict[str, Any]:
    """``read(meta, rec)`` on the recording at ``path`` opened with only ``table`` (``rec`` None
    where it has no such table), with the recording's path and id."""
    from aveas_format.io.container import Container
    from aveas_format.io.reader import open_recording, read_meta, table_names_present

    with local_copy(path) as local:
        with Container(local) as c:
            meta, _ = read_meta(c)
            present = table_names_present(c, meta)
        rec = open_recording(local, tables=[table], verify=False) if table in present else None
        return {"path": path, "recording_id": meta.recording_id, **read(meta, rec)}


def recording_situations(path: str) -> dict[str, Any]:
    """The participant rows of one recording's ``derived/criticality_summary`` (a task), as
    columns, with the recording's path and id; empty where the recording has no summary."""
    def read(meta, rec) -> dict[str, Any]:
        if rec is None:
            return {"rows": [], "has_summary": False}
        return {"rows": [r for r in rec.derived["criticality_summary"].to_pylist()
                         if str(r["scope"]) == "participant"], "has_summary": True}

    return _with_table(path, "derived/criticality_summary", read)


def _collect(task, flag: str, paths: Iterable[str | Path], workers: int | None,
             scheduler: str | None, progress: bool,
             on_result: Callable[[TaskResult], None] | None):
    """``task`` on every recording in parallel: ``(values, missing, failed)``, ``missing`` the
    paths whose value's ``flag`` is false, ``failed`` ``(path, error)`` of those not read."""
    values: list[dict[str, Any]] = []
    missing: list[str] = []
    failed: list[tuple[str, str]] = []
    for r in map_recordings(task, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                            progress=progress, description="find"):
        if on_result is not None:
            on_result(r)
        if not r.ok:
            failed.append((r.item, r.error))
            continue
        values.append(r.value)
        if not r.value[flag]:
            missing.append(r.value["path"])
    return values, missing, failed


def situations(paths: Iterable[str | Path], *, workers: int | None = 1,
               scheduler: str | None = None, progress: bool = False,
               on_result: Callable[[TaskResult], None] | None = None):
    """Every participant's situation in every recording, one row each (a pyarrow table with
    ``path``, ``recording_id``, ``participant_id``, ``other_id``, ``time`` and the measures), and
    the recordings without a summary (``(table, missing, failed)``)."""
    import pyarrow as pa

    rows: list[dict[str, Any]] = []
    values, missing, failed = _collect(recording_situations, "has_summary", paths, workers,
                                       scheduler, progress, on_result)
    for v in values:
        for s in v["rows"]:
            rows.append({"path": v["path"], "recording_id": v["recording_id"],
                         "participant_id": s["participant_id"], "other_id": s["min_ttc_other_id"],
                         "time": s["min_ttc_time"], "ttc_kind": s["min_ttc_kind"],
                         **{k: s.get(k) for k in MEASURES},
                         **{sd: s.get(sd) for sd in MEASURES.values() if sd},
                         "worst_events": s.get("worst_events") or []})
    fields = [("path", pa.string()), ("recording_id", pa.string()),
              ("participant_id", pa.int64()), ("other_id", pa.int64()), ("time", pa.float64()),
              ("ttc_kind", pa.string())]
    for k, sd in MEASURES.items():
        fields.append((k, pa.int64() if k in ("ttc_samples_below", "near_misses",
                                              "hard_braking") else pa.float64()))
        if sd:
            fields.append((sd, pa.float64()))
    fields.append(("worst_events", pa.list_(pa.int64())))
    schema = pa.schema(fields)
    table = pa.Table.from_pylist(rows, schema=schema) if rows else schema.empty_table()
    return table, missing, failed


def rank(table, where: str | None = None, by: str = "min_ttc", top: int | None = 20):
    """The situations matching ``where`` (:func:`parse_where`), most critical by ``by`` first
    (ascending for ``min_ttc``, ``min_psd``, ``min_pet``; descending otherwise), at most ``top``."""
    import pyarrow as pa
    import pyarrow.compute as pc

    if by not in MEASURES:
        raise ValueError(f"--by: unknown measure {by!r}; known: {', '.join(MEASURES)}")
    ops = {"<": pc.less, "<=": pc.less_equal, ">": pc.greater, ">=": pc.greater_equal,
           "==": pc.equal, "!=": pc.not_equal}
    for name, op, num in parse_where(where):
        table = table.filter(pc.fill_null(ops[op](table.column(name), num), False))
    table = table.filter(pc.is_valid(table.column(by)))
    order = "ascending" if by in SMALLER_IS_WORSE else "descending"
    table = table.sort_by([(by, order), ("recording_id", "ascending"),
                           ("participant_id", "ascending")])
    # a pair's moment is one situation: both participants' rows name it (keep the first)
    seen: set[tuple] = set()
    keep = []
    for k, (path, a, b, t) in enumerate(zip(*(table.column(c).to_pylist() for c in
                                              ("path", "participant_id", "other_id", "time")))):
        key = (path, frozenset((a, b)), t)
        if b is None or t is None or key not in seen:
            keep.append(k)
            seen.add(key)
        if top is not None and len(keep) >= top:
            break
    return table.take(pa.array(keep, pa.int64()))


def recording_events(path: str) -> dict[str, Any]:
    """The derived conflicts and near misses of one recording (a task), most critical first
    (:func:`aveas_format.derive.events.worst_events`), with the recording's path and id."""
    from aveas_format.derive.events import worst_events

    def read(meta, rec) -> dict[str, Any]:
        if rec is None:
            return {"rows": [], "has_events": False}
        rows = worst_events(rec.events)
        derived = any(e.table == "events" for e in meta.derived) or bool(rows) or (
            rec.events is not None and "origin" in rec.events.column_names and any(
                str(o) == "derived" for o in rec.events.column("origin").to_pylist()))
        return {"rows": rows, "has_events": derived}

    return _with_table(path, "events", read)


#: the columns of :func:`critical_events`' table
EVENT_FIELDS = (("path", "string"), ("recording_id", "string"), ("event_id", "int64"),
                ("kind", "string"), ("participant_id", "int64"), ("other_id", "int64"),
                ("relation", "string"), ("time_start", "float64"), ("time_end", "float64"),
                ("time", "float64"), ("metric", "string"), ("value", "float64"),
                ("value_std", "float64"), ("duration", "float64"),
                ("collision_probability", "float64"), ("collision_probability_std", "float64"))


def critical_events(paths: Iterable[str | Path], *, workers: int | None = 1,
                    scheduler: str | None = None, progress: bool = False,
                    on_result: Callable[[TaskResult], None] | None = None):
    """Every derived conflict and near miss of every recording, one row each (a pyarrow table of
    :data:`EVENT_FIELDS`; ``participant_id``/``other_id`` its pair, ``time`` its extreme), the
    recordings without derived events, and the failures (``(table, missing, failed)``)."""
    import pyarrow as pa

    rows: list[dict[str, Any]] = []
    values, missing, failed = _collect(recording_events, "has_events", paths, workers, scheduler,
                                       progress, on_result)
    for v in values:
        for e in v["rows"]:
            ids = list(e["participant_ids"] or []) + [None, None]
            rows.append({"path": v["path"], "recording_id": v["recording_id"],
                         "participant_id": ids[0], "other_id": ids[1],
                         "time": e.get("time_extreme") if e.get("time_extreme") is not None
                         else e["time_start"],
                         **{k: e.get(k) for k, _ in EVENT_FIELDS if k not in (
                             "path", "recording_id", "participant_id", "other_id", "time")}})
    schema = pa.schema([(k, getattr(pa, t)()) for k, t in EVENT_FIELDS])
    table = pa.Table.from_pylist(rows, schema=schema) if rows else schema.empty_table()
    return table, missing, failed


def rank_events(table, where: str | None = None, top: int | None = 20):
    """The events matching ``where`` (on :data:`EVENT_MEASURES`), most likely to collide first
    (then the smaller TTC or PET), at most ``top``."""
    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc

    ops = {"<": pc.less, "<=": pc.less_equal, ">": pc.greater, ">=": pc.greater_equal,
           "==": pc.equal, "!=": pc.not_equal}
    for name, op, num in parse_where(where, EVENT_MEASURES):
        table = table.filter(pc.fill_null(ops[op](table.column(name), num), False))
    p = pc.fill_null(table.column("collision_probability"), 0.0)
    v = table.column("value").to_numpy(zero_copy_only=False).astype(float)
    drac = (table.column("metric").to_numpy(zero_copy_only=False) == "drac")
    key = np.lexsort((np.where(drac, -v, v), drac, -p.to_numpy(zero_copy_only=False)))
    if top is not None:
        key = key[:top]
    return table.take(pa.array(key, pa.int64()))


def find(paths: Iterable[str | Path], *, where: str | None = None, by: str = "min_ttc",
         top: int | None = 20, workers: int | None = 1, scheduler: str | None = None,
         progress: bool = False):
    """:func:`situations` of a dataset, filtered and ranked by :func:`rank`."""
    parse_where(where)  # fail before any work
    table, _, _ = situations(paths, workers=workers, scheduler=scheduler, progress=progress)
    return rank(table, where, by, top)


def cut_name(situation: dict[str, Any]) -> str:
    """A file stem for a situation: ``RECORDING_pPID_with_OTHER_tTIME``."""
    other = situation.get("other_id")
    t = situation.get("time")
    return (f"{situation['recording_id']}_p{situation['participant_id']}"
            + (f"_with_{other}" if other is not None else "")
            + (f"_t{t:.2f}".replace(".", "_") if t is not None else ""))


def cut_out(situation: dict[str, Any], out_dir: str | Path, *, before_s: float = 5.0,
            after_s: float = 3.0, overwrite: bool = False, scenario: bool = True
            ) -> list[Path]:
    """Write ``situation`` (a row of :func:`find`) as a small recording — its participant and the
    other participant of the moment, from ``before_s`` before to ``after_s`` after it, with the
    map, the events in the window and no derived tables (derive it again) — and, with
    ``scenario``, as an OpenSCENARIO file for replay next to it. Times start at 0 at the window's
    start (``start_time`` moves with it). Returns the paths written."""
    import datetime as _dt

    import numpy as np
    import pyarrow as pa
    import pyarrow.compute as pc

    from aveas_format.io.reader import open_recording
    from aveas_format.io.recording import Recording

    out_dir = Path(out_dir)
    stem = cut_name(situation)
    target = out_dir / f"{stem}.aveas"
    xosc = out_dir / f"{stem}.xosc"
    for p in (target, xosc) if scenario else (target,):
        if p.exists() and not overwrite:
            raise AveasError(f"{p}: exists; pass --overwrite to replace it")
    t_mid = situation.get("time")
    if t_mid is None:
        raise AveasError(f"{situation['path']}: participant {situation['participant_id']} has no "
                         "critical moment (no TTC) to cut out")
    who = [situation["participant_id"]] + ([situation["other_id"]]
                                           if situation.get("other_id") is not None else [])
    with local_copy(situation["path"]) as local:
        rec = open_recording(local)
    t0, t1 = float(t_mid) - before_s, float(t_mid) + after_s
    s = rec.states
    keep = pc.and_(pc.is_in(s.column("participant_id"), pa.array(who, pa.int64())),
                   pc.and_(pc.greater_equal(s.column("time"), t0),
                           pc.less_equal(s.column("time"), t1)))
    states = s.filter(keep)
    if not states.num_rows:
        raise AveasError(f"{situation['path']}: no states of participants {who} in "
                         f"[{t0:.2f}, {t1:.2f}] s")
    start = float(pc.min(states.column("time")).as_py())
    end = float(pc.max(states.column("time")).as_py())
    states = states.set_column(states.schema.get_field_index("time"), "time",
                               pc.subtract(states.column("time"), start))
    tables: dict[str, pa.Table] = {
        "states": states,
        "participants": rec.participants.filter(
            pc.is_in(rec.participants.column("participant_id"), pa.array(who, pa.int64()))),
    }
    def window(t: pa.Table, mask: np.ndarray) -> pa.Table | None:
        """The rows of an interval table overlapping the window, clipped and shifted to it."""
        within = ((t.column("time_end").to_numpy(zero_copy_only=False) >= start)
                  & (t.column("time_start").to_numpy(zero_copy_only=False) <= end))
        t = t.filter(pa.array(mask & within))
        if not t.num_rows:
            return None
        for c in ("time_start", "time_end"):
            v = np.clip(t.column(c).to_numpy(zero_copy_only=False), start, end) - start
            t = t.set_column(t.schema.get_field_index(c), c, pa.array(v, pa.float64()))
        return t

    if rec.unobserved is not None:
        tables["unobserved"] = window(rec.unobserved, np.ones(rec.unobserved.num_rows, bool)) \
            or rec.unobserved.slice(0, 0)
    if rec.events is not None and rec.events.num_rows:
        pids = rec.events.column("participant_ids").to_pylist()
        ev = window(rec.events, np.array([bool(set(p or []) & set(who)) for p in pids]))
        if ev is not None:
            # copies of events: their derivation's record (input hashes) is the source's
            md = {k: v for k, v in (ev.schema.metadata or {}).items() if k != b"aveas_derived"}
            tables["events"] = ev.replace_schema_metadata(md or None)
    meta = rec.meta.model_copy(deep=True)
    meta.recording_id = stem
    meta.title = (f"{rec.meta.title or rec.meta.recording_id}: participant "
                  f"{situation['participant_id']}" + (f" and {situation['other_id']}"
                                                      if situation.get("other_id") is not None
                                                      else "")
                  + f", {t0:.2f}-{t1:.2f} s")
    meta.derived = []
    meta.tables = {}
    if meta.start_time is not None:
        st = meta.start_time
        if isinstance(st, str):
            st = _dt.datetime.fromisoformat(st.replace("Z", "+00:00"))
        meta.start_time = (st + _dt.timedelta(seconds=start)).strftime("%Y-%m-%dT%H:%M:%S.%fZ")
    meta.duration_s = end - start
    small = Recording(meta, tables, rec.map_source)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = [small.write(target, overwrite=overwrite)]
    if scenario:
        from aveas_format.converters.registry import get_converter

        conv = get_converter("openscenario", "export")
        written += list(conv(small, xosc, options={}))
    return written


__all__ = ["EVENT_FIELDS", "EVENT_MEASURES", "MEASURES", "critical_events", "cut_name",
           "cut_out", "find", "parse_where", "rank", "rank_events", "recording_events",
           "recording_situations", "situations"]
