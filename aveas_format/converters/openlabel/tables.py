"""The OpenLABEL import's tables and metadata (the last steps of
:func:`aveas_format.converters.openlabel.read.openlabel_to_recording`): the events, interior,
environment and unobserved tables and the static conditions — from the ``aveas_format`` extension
where the file has it, else from the profile's events and contexts — the recording's metadata, and
the derived tables of our own export restored.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pyarrow as pa

from aveas_format.converters.openlabel.profile import (
    EXT,
    PROFILE_TO_METHOD,
    TYPE_TO_EVENT,
    attributes_of,
    conditions_from,
    enum_value,
    first_value,
)
from aveas_format.errors import report_source
from aveas_format.io.tablejson import table_from_json


def tables_of(ol: dict[str, Any], ext: dict[str, Any] | None, frame_time: dict[int, float],
            pid_of: dict[str, int], interior: dict[str, list]) -> tuple[dict[str, Any], dict | None, bool]:
    """``(events, unobserved, environment and interior tables, static conditions, staged)``: the
    tables from the extension, else from the profile's events, interior attributes and contexts."""
    tables_ext = (ext or {}).get("tables") or {}
    events = table_from_json(tables_ext.get("events"), "events")
    unobserved = table_from_json(tables_ext.get("unobserved"), "unobserved")
    environment = table_from_json(tables_ext.get("environment"), "environment")
    interior_t = table_from_json(tables_ext.get("interior"), "interior")
    if ext is None:
        events = profile_events(ol, frame_time, pid_of)
        if interior:
            interior_t = pa.table({c: pa.array(v) for c, v in interior.items()
                                   if c in ("participant_id", "time") or any(x is not None for x in v)})
    conditions, environment_rows, staged = profile_contexts(ol, frame_time)
    if ext is None and environment_rows:
        environment = pa.table({k: [r.get(k) for r in environment_rows]
                                for k in sorted({k for r in environment_rows for k in r})})
    tables = {"unobserved": unobserved, "events": events, "environment": environment, "interior": interior_t}
    return tables, conditions, staged


def recording_metadata(options, md: dict[str, Any], rmeta: dict[str, Any],
                        ext: dict[str, Any] | None, path: Path | None, n: int, ego_seen: bool,
                        staged: bool, conditions: dict[str, Any] | None
                        ) -> tuple[dict[str, Any], dict[str, Any]]:
    """``(method, partner, provenance, acquisition, rights; the other recording.json fields)``:
    the options beat our own export's recording.json, which beats the profile's metadata."""
    method = options.method or ((rmeta.get("acquisition") or {}).get("method")) or \
        PROFILE_TO_METHOD.get(str(enum_value(md.get("acquisition_method"))), None) or \
        ("road_vehicle" if ego_seen else "infrastructure_camera")
    partner = options.partner or (rmeta.get("acquisition") or {}).get("partner") or \
        md.get("acquisition_partner") or md.get("annotator") or "unknown"
    provenance = options.provenance or rmeta.get("provenance") or ("staged" if staged else "natural")
    acq = dict(rmeta.get("acquisition") or {})
    acq.pop("method", None)
    acq.pop("partner", None)
    if not acq and path is not None:
        acq = {"platform": f"imported from OpenLABEL {path.name}"}
    rights = rmeta.get("rights") or {
        "right_of_use": str(enum_value(md.get("right_of_use") or options.right_of_use)),
        "license": options.license, "owner": options.owner or partner}
    if options.owner or options.license != "unspecified":
        rights = {**rights, "license": options.license if options.license != "unspecified"
                  else rights.get("license", "unspecified"), "owner": options.owner or rights.get("owner") or partner}
    kw: dict[str, Any] = {}
    for key in ("title", "description", "coverage", "conditions", "thresholds", "extras", "location",
                "duration_s", "nominal_rate_hz"):
        if rmeta.get(key) is not None:
            kw[key] = rmeta[key]
    if "thresholds" not in kw and ext is None and any(
            md.get(k) is not None for k in ("threshold_gttc", "threshold_pret", "threshold_thw")):
        kw["thresholds"] = {"ttc_s": md.get("threshold_gttc"), "pet_s": md.get("threshold_pret"),
                            "thw_s": md.get("threshold_thw")}
        kw["thresholds"] = {k: float(v) for k, v in kw["thresholds"].items() if v and v > 0}
    if ext is not None:
        given = set(ext.get("thresholds_given") or [])
        if "thresholds" in kw:
            kw["thresholds"] = {k: v for k, v in kw["thresholds"].items() if k in given}
            if not kw["thresholds"]:
                del kw["thresholds"]
    if "conditions" not in kw and conditions:
        kw["conditions"] = conditions
    if "title" not in kw and ext is None and md.get("name"):  # ours: recording.json has it (or none)
        kw["title"] = str(md["name"])
    if options.title:
        kw["title"] = options.title
    if not n:
        kw.setdefault("duration_s", 0.0)
        kw.setdefault("nominal_rate_hz", options.rate_hz)
    meta_args = {"method": method, "partner": partner, "provenance": provenance, "acquisition": acq,
                 "rights": rights}
    return meta_args, kw


def restore_derived(rec, ext: dict[str, Any], path: Path | None = None) -> None:
    """The derived tables and recording.json ``derived`` entries of this library's own export."""
    from aveas_format.schema.metadata import DerivedEntry
    from aveas_format.schema.tables import TABLES

    for name, obj in sorted((ext.get("derived") or {}).items()):
        spec = TABLES.get(f"derived/{name}")
        if spec is None or not isinstance(obj, dict):
            report_source("source.openlabel.extension_skipped",
                          f"OpenLABEL extension: unknown derived table {name!r} skipped", stacklevel=3,
                          file=str(path) if path is not None else None,
                          json_path=f"$.openlabel.metadata.{EXT}.derived[{name!r}]")
            continue
        table = table_from_json(obj, spec.name)
        if table is not None:
            # types as declared, columns and rows in the order they had (as exported)
            rec.derived[name] = table.select([c for c in obj.get("columns") or {}
                                              if c in table.column_names])
    entries = []
    for i, e in enumerate(ext.get("derived_entries") or []):
        try:
            entries.append(DerivedEntry.model_validate(e))
        except Exception as err:  # noqa: BLE001 — a damaged entry: the table is then reported stale
            report_source("source.openlabel.extension_skipped",
                          f"OpenLABEL extension: derived entry skipped ({err})", stacklevel=3,
                          file=str(path) if path is not None else None,
                          json_path=f"$.openlabel.metadata.{EXT}.derived_entries[{i}]")
    if entries:
        rec.meta.derived = entries



def profile_events(ol: dict[str, Any], frame_time: dict[int, float], pid_of: dict[str, int]):
    evs = ol.get("events") or {}
    rows = []
    for k, ev in evs.items():
        etype = str(enum_value((ev or {}).get("type") or ""))
        kind = TYPE_TO_EVENT.get(etype) or TYPE_TO_EVENT.get(etype.replace("_", " "))
        if kind is None and etype.replace(" ", "_") in {"near_miss", "accident", "lane_change", "cut_in",
                                                        "overtaking", "following", "turning", "parking",
                                                        "hard_braking", "handover_to_driver",
                                                        "driver_intervention"}:
            kind = etype.replace(" ", "_")
        if kind is None:
            continue
        attrs = attributes_of(ev.get("event_data"))
        a = first_value(attrs, "event_participant/role_a_id")
        b = first_value(attrs, "event_participants/role_b_ids") or []
        ids = [pid_of[str(v)] for v in ([a] if a is not None else []) + list(b) if str(v) in pid_of]
        fi = (ev.get("frame_intervals") or [{}])[0]
        fs, fe = fi.get("frame_start"), fi.get("frame_end")
        if fs is None or fs not in frame_time:
            continue
        rows.append({"event_id": int(k) if str(k).isdigit() else len(rows), "kind": kind,
                     "time_start": frame_time[fs], "time_end": frame_time.get(fe, frame_time[fs]),
                     "participant_ids": ids,
                     "roles": (["role_a"] if a is not None else []) + ["role_b"] * (len(ids) - (a is not None)),
                     "origin": "annotated"})
    if not rows:
        return None
    return pa.table({k: [r[k] for r in rows] for k in rows[0]})


def profile_contexts(ol: dict[str, Any], frame_time: dict[int, float]):
    conditions: dict[str, Any] = {}
    env_rows: list[dict[str, Any]] = []
    staged = False
    for ctx in (ol.get("contexts") or {}).values():
        ctx = ctx or {}
        name, typ = str(ctx.get("name", "")), str(ctx.get("type", ""))
        cd = ctx.get("context_data") or {}
        if "scenario" in name.lower() or typ == "ScenarioContext":
            staged |= bool(first_value(attributes_of(cd), "scenario/is_staged", False))
        elif "environment" in name.lower() or typ == "EnvironmentContext":
            c = conditions_from(cd)
            fis = ctx.get("frame_intervals")
            if fis:
                for fi in fis:
                    fs, fe = fi.get("frame_start"), fi.get("frame_end")
                    if fs in frame_time:
                        env_rows.append({"time_start": frame_time[fs],
                                         "time_end": frame_time.get(fe, frame_time[fs]), **c})
            else:
                conditions.update(c)
    return conditions or None, env_rows, staged
