"""Build a valid recording from plain arrays: for converters, tests and users.

:func:`build_recording` takes participants and states as dicts of arrays (or pyarrow Tables) and a
map, and fills what can be derived: source ids, roles and provenance from the recording's
provenance; heading from the direction of motion and velocity from positions where missing; lon/lat
through the CRS (:mod:`aveas_format.crs`); road coordinates through the map
(:mod:`aveas_format.mapref.roads`); duration, nominal
rate, location and the ``tables``/``map`` entries of recording.json.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
from pydantic import ValidationError

from aveas_format.errors import FormatError, MissingCrsError
from aveas_format.io.arrow import conform
from aveas_format.io.container import sha256_of
from aveas_format.io.recording import Recording
from aveas_format.io.writer import opendrive_version, prepare_table
from aveas_format.schema.enums import AcquisitionMethod, Provenance, RecordingProvenance, Role
from aveas_format.schema.metadata import RecordingMeta
from aveas_format.safeio import xml_source
from aveas_format.schema.tables import TABLES
from aveas_format.crs import LocalFrame
from aveas_format.mapref.roads import road_coordinates
from aveas_format.numeric import central_differences, same_participant, wrap_angle
from aveas_format.opendrive import load_map
from aveas_format.schema.versions import FORMAT_VERSION

TableLike = pa.Table | Mapping[str, Any]
_SIMULATED_METHODS = {AcquisitionMethod.TRAFFIC_SIMULATION, AcquisitionMethod.DRIVING_SIMULATOR}


def _table(data: TableLike | None, name: str) -> pa.Table | None:
    if data is None:
        return None
    if isinstance(data, pa.Table):
        return data
    try:
        return pa.table({k: (v if isinstance(v, (pa.Array, pa.ChunkedArray)) else _array(v))
                         for k, v in data.items()})
    except (pa.ArrowInvalid, pa.ArrowTypeError, ValueError) as e:
        raise FormatError(f"cannot build table {name}: {e}") from None


def _array(v: Any) -> pa.Array:
    a = np.asarray(v) if not isinstance(v, list) else v
    if isinstance(a, np.ndarray) and a.ndim == 2:  # PMF matrix -> list column, conform makes structs
        return pa.array(list(a.astype(np.float32)), pa.list_(pa.float32()))
    return pa.array(a)


def load_map_bytes(source: str | bytes | Path) -> bytes:
    """The bytes of a map given as a path, XML text or bytes."""
    return xml_source(source)[0]


#: an example CRS for maps without ``<geoReference>``: a transverse Mercator at the site
EXAMPLE_CRS = "+proj=tmerc +lat_0=48.1 +lon_0=11.5 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m"


def check_crs(crs: str | None, geo_reference: str | None) -> str:
    """The recording's CRS: the map's ``geo_reference``, else ``crs`` (FORMAT.md: where the map has
    no geoReference, ``crs`` alone defines the frame). A ``crs`` that differs from the map's
    geoReference is an error (the map fixes the frame); neither raises
    :class:`~aveas_format.errors.MissingCrsError`."""
    from aveas_format.crs import crs_equal, parse_crs

    if crs and geo_reference:
        if not crs_equal(crs, geo_reference):
            raise FormatError(f"crs {crs!r} differs from the map's <geoReference> "
                              f"{geo_reference!r}: the map fixes the frame; leave crs out")
        return geo_reference
    if crs:
        parse_crs(crs)  # a FormatError naming an unreadable CRS
        return crs
    if geo_reference:
        return geo_reference
    raise MissingCrsError("the map has no <geoReference>: give the recording's CRS with --crs "
                          f"(API: crs=), e.g. a transverse Mercator at the site, '{EXAMPLE_CRS}'")


def velocity_from_positions(pid: np.ndarray, t: np.ndarray, x: np.ndarray, y: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Velocity from positions within each participant (:func:`aveas_format.numeric.central_differences`:
    second order on uneven sampling, one-sided at track ends). A participant with one sample gets
    velocity 0. Rows must be sorted by (participant, time)."""
    vx, vy, _, _ = central_differences(pid, t, x, y, std=False)
    return np.nan_to_num(vx), np.nan_to_num(vy)


def heading_from_velocity(pid: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                          min_speed: float = 0.5) -> np.ndarray:
    """Heading from the direction of motion; below ``min_speed`` the last moving heading is held
    (forward-filled within the participant, then back-filled for a track that starts at rest)."""
    h = np.arctan2(vy, vx)
    moving = np.hypot(vx, vy) >= min_speed
    n = len(h)
    idx = np.where(moving, np.arange(n), -1)
    starts = np.r_[0, np.flatnonzero(~same_participant(pid)) + 1] if n else np.array([], int)
    group = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, n])) if n else np.array([], int)
    # forward fill within each participant
    idx_ff = np.maximum.accumulate(np.where(idx >= 0, idx, -1))
    idx_ff = np.where((idx_ff >= 0) & (group[np.maximum(idx_ff, 0)] == group), idx_ff, -1)
    # back fill (first moving sample of the participant) where nothing came before
    nxt = np.where(idx >= 0, idx, n)
    idx_bf = np.minimum.accumulate(nxt[::-1])[::-1]
    ok_bf = (idx_bf < n) & (group[np.minimum(idx_bf, n - 1)] == group) if n else idx_bf < n
    src = np.where(idx_ff >= 0, idx_ff, np.where(ok_bf, idx_bf, -1))
    out = np.where(src >= 0, h[np.maximum(src, 0)], 0.0)
    return out


def build_recording(
    *,
    map_source: str | bytes | Path,
    participants: TableLike,
    states: TableLike,
    unobserved: TableLike | None = None,
    events: TableLike | None = None,
    environment: TableLike | None = None,
    interior: TableLike | None = None,
    crs: str | None = None,
    method: str | AcquisitionMethod = AcquisitionMethod.TRAFFIC_SIMULATION,
    partner: str = "unknown",
    provenance: str | None = None,
    start_time: str = "1970-01-01T00:00:00Z",
    nominal_rate_hz: float | None = None,
    duration_s: float | None = None,
    recording_id: str | None = None,
    rights: Mapping[str, Any] | None = None,
    license: str | None = None,
    reference: bool = True,
    check_map_crs: bool = False,
    **meta: Any,
) -> Recording:
    """A valid in-memory recording from plain arrays (see module doc).

    ``map_source`` is the OpenDRIVE text/bytes or a path to a .xodr file. ``partner``,
    ``start_time`` and ``license`` (or the whole ``rights``) are what only a person can state:
    without them the recording carries stand-ins ("unknown", 1970-01-01, "unspecified") that the
    validator flags (a simulation's time zero excepted). Extra keyword arguments are
    recording.json fields (``title``, ``acquisition`` overrides as a dict, ``coverage``,
    ``conditions``, ``thresholds``, ``extras``...). ``reference=False`` keeps road coordinates as
    given (or null) instead of computing them from the map. ``crs`` defaults to the map's
    geoReference (one of them is needed: :class:`~aveas_format.errors.MissingCrsError`);
    ``check_map_crs=True`` (a CRS a user gave, the importers' ``crs`` option) refuses a ``crs``
    that differs from the map's geoReference. Without it a differing ``crs`` is taken as given
    (``validate`` reports it: geo.crs_mismatch).
    """
    map_bytes = load_map_bytes(map_source)
    net = load_map(map_bytes)
    method = AcquisitionMethod(method)
    if provenance is None:
        provenance = "simulated" if method in _SIMULATED_METHODS else "natural"
    rec_prov = RecordingProvenance(provenance)
    if check_map_crs or not crs:
        crs = check_crs(crs, net.header.geo_reference)

    p = _table(participants, "participants")
    assert p is not None and states is not None
    p = _fill_participants(p, rec_prov)
    s = states_table(states, LocalFrame(crs, offset=net.header.offset), net if reference else None)

    t = s.column("time").to_numpy() if s.num_rows else np.zeros(0)
    pid = s.column("participant_id").to_numpy() if s.num_rows else np.zeros(0, np.int64)
    if nominal_rate_hz is None:
        same = same_participant(pid)
        dt = np.diff(t)[same]
        dt = dt[dt > 0]
        nominal_rate_hz = float(round(1.0 / np.median(dt), 6)) if len(dt) else 1.0
    if duration_s is None:
        duration_s = float(t.max()) if len(t) else 0.0
    lon = s.column("lon").to_numpy() if s.num_rows else np.array([0.0])
    lat = s.column("lat").to_numpy() if s.num_rows else np.array([0.0])
    acq = {"method": method.value, "partner": partner}
    acq.update(meta.pop("acquisition", {}) or {})
    md: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "tables": {},
        "recording_id": recording_id or str(uuid.uuid4()),
        "start_time": start_time,
        "duration_s": duration_s,
        "nominal_rate_hz": nominal_rate_hz,
        "acquisition": acq,
        "provenance": rec_prov.value,
        "location": {"lon": float(np.mean(lon)), "lat": float(np.mean(lat))},
        "crs": crs,
        "map": {"file": "map.xodr", "sha256": sha256_of(map_bytes),
                "opendrive_version": opendrive_version(map_bytes)},
        "rights": dict(rights or {"right_of_use": "research_only",
                                  "license": license or "unspecified", "owner": partner}),
    }
    md.update(meta)
    try:
        meta_model = RecordingMeta.model_validate(md)
    except ValidationError as e:
        from aveas_format.io.reader import format_validation_error

        raise FormatError(f"invalid recording metadata: {format_validation_error(e)}") from None
    tables = {"participants": p, "states": s}
    for name, data in (("unobserved", unobserved), ("events", events),
                       ("environment", environment), ("interior", interior)):
        tab = _table(data, name)
        if tab is not None:
            tables[name] = prepare_table(tab, TABLES[name])
    rec = Recording(meta=meta_model, tables=tables, map_source=map_bytes)
    rec._map = net
    return rec


def _fill_participants(p: pa.Table, prov: RecordingProvenance) -> pa.Table:
    n = p.num_rows
    for need in ("participant_id", "class", "length", "width"):
        if need not in p.column_names:
            raise FormatError(f"participants: column {need!r} is required")
    if "source_id" not in p.column_names:
        p = p.append_column("source_id", p.column("participant_id").cast(pa.string()))
    part_prov = Provenance.NATURAL.value if prov is RecordingProvenance.MIXED else prov.value
    if "provenance" not in p.column_names:
        p = p.append_column("provenance", pa.array([part_prov] * n, pa.string()))
    if "role" not in p.column_names:
        provs = p.column("provenance").cast(pa.string()).to_pylist()
        roles = [Role.SIMULATED_AGENT.value if v == "simulated" else
                 Role.STAGED_ACTOR.value if v == "staged" else Role.OBSERVED.value for v in provs]
        p = p.append_column("role", pa.array(roles, pa.string()))
    return prepare_table(p, TABLES["participants"])


def states_table(states: TableLike, frame, net) -> pa.Table:
    """The states as a recording has them: the format's columns and types, filled by
    :func:`fill_states` (an importer that writes its states in parts: a bucket of whole
    participants at a time)."""
    s = prepare_table(conform(_table(states, "states"), TABLES["states"]), TABLES["states"])
    return fill_states(s, frame, net)


def fill_states(s: pa.Table, frame, net) -> pa.Table:
    """The states' velocity, heading, WGS 84 and (``net``: from the map) road coordinates where
    ``s`` has not got them (rows sorted by participant and time; whole tracks: an importer that
    writes its states in parts gives them a participant at a time)."""
    for need in ("participant_id", "time", "x", "y"):
        if need not in s.column_names:
            raise FormatError(f"states: column {need!r} is required")
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x = s.column("x").to_numpy()
    y = s.column("y").to_numpy()
    cols = dict(zip(s.column_names, s.columns))
    if "vx" not in cols or "vy" not in cols:
        vx, vy = velocity_from_positions(pid, t, x, y)
        cols["vx"], cols["vy"] = pa.array(vx), pa.array(vy)
    if "heading" not in cols:
        h = heading_from_velocity(pid, np.asarray(cols["vx"]), np.asarray(cols["vy"]))
        cols["heading"] = pa.array(h)
    else:
        cols["heading"] = pa.array(wrap_angle(np.asarray(cols["heading"])))
    if "lon" not in cols or "lat" not in cols:
        lon, lat = frame.to_wgs84(x, y)
        cols["lon"], cols["lat"] = pa.array(lon), pa.array(lat)
    if net is not None and "road_id" not in cols:
        ref = road_coordinates(net, pid, t, x, y, np.asarray(cols["heading"]))
        cols.update(ref)
    for c in ("road_id", "lane_id", "road_s", "road_t"):
        if c not in cols:
            cols[c] = pa.nulls(s.num_rows, pa.string() if c == "road_id" else pa.float64())
    out = pa.table(cols)
    return prepare_table(out, TABLES["states"])
