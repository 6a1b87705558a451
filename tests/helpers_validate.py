"""A fixture factory: a small recording with no finding at all, and mutations of it.

``scene()`` returns the plain arrays and metadata of a clean recording (four vehicles in three lanes of
the straight test map, measured aerial data with full uncertainty, an occlusion away from the traffic,
every SHOULD field of recording.json filled); ``build(scene)`` turns it into a Recording through
``build_recording`` (which derives lon/lat and road coordinates, so mutations of positions stay
consistent). Mutations either edit the scene before building (physically consistent changes) or the
built tables (inconsistencies between columns).
"""

from __future__ import annotations

import copy

import numpy as np
import pyarrow as pa
import shapely

from aveas_format.io.arrow import pmf_array
from aveas_format.mapref.build import build_recording
from aveas_format.schema.pmf import one_hot
from aveas_format.schema.tables import TABLES

from helpers_common import STRAIGHT_MAP

MAP = STRAIGHT_MAP.read_text()
CRS = "+proj=tmerc +lat_0=48.9 +lon_0=8.35 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
RATE = 25.0
STEPS = 150  # 6 s

#: class, lane, x0 [m], speed [m/s], length, width
VEHICLES = [("car", -1, 100.0, 25.0, 4.5, 1.8), ("van", -2, 60.0, 28.0, 5.5, 2.0),
            ("truck", -1, 20.0, 22.0, 12.0, 2.5), ("car", -3, 150.0, 33.0, 4.4, 1.8)]


def track(x0: float, lane: int, v: np.ndarray | float, steps: int = STEPS, rate: float = RATE,
          heading: float | None = None) -> dict[str, np.ndarray]:
    """One participant's arrays: positions integrate the velocity exactly (trapezoid rule)."""
    t = np.arange(steps) / rate
    v = np.broadcast_to(np.asarray(v, dtype=np.float64), t.shape).copy()
    x = x0 + np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]
    y = np.full(steps, (lane + 0.5) * 3.5)
    h = np.where(v >= 0, 0.0, np.pi) if heading is None else np.full(steps, heading)
    return {"time": t, "x": x, "y": y, "vx": v, "vy": np.zeros(steps), "heading": h}


def scene() -> dict:
    """Plain data of the clean recording (a fresh deep copy each call)."""
    tracks = [track(x0, lane, v) for _, lane, x0, v, _, _ in VEHICLES]
    n = len(VEHICLES)
    classes = np.array([c[0] for c in VEHICLES], dtype=object)
    pmf = 0.9 * one_hot(classes, "class")
    pmf[:, [3, 11, 12]] += 0.1 / 3  # car, truck, van
    return {
        "participants": {
            "participant_id": np.arange(n, dtype=np.int64),
            "source_id": [f"track-{i}" for i in range(n)],
            "class": classes,
            "class_pmf": pmf,
            "length": np.array([c[4] for c in VEHICLES]),
            "width": np.array([c[5] for c in VEHICLES]),
            "length_std": np.full(n, 0.2),
            "width_std": np.full(n, 0.1),
            "role": ["observed"] * n,
            "provenance": ["natural"] * n,
        },
        "tracks": tracks,
        "std": {"x_std": 0.1, "y_std": 0.1, "heading_std": 0.02, "vx_std": 0.2, "vy_std": 0.2},
        "extra_states": {},
        "unobserved": {
            "region_id": np.array([0], np.int64),
            "time_start": np.array([0.0]),
            "time_end": np.array([(STEPS - 1) / RATE]),
            "kind": ["occlusion"],
            "geometry": [shapely.to_wkb(shapely.box(900.0, -10.5, 950.0, 0.0))],
            "sensor_id": ["cam"],
        },
        "events": None,
        "map": MAP,
        "meta": {
            "crs": None,
            "method": "aerial",
            "partner": "Test Institute",
            "provenance": "natural",
            "start_time": "2024-05-13T08:15:00Z",
            "nominal_rate_hz": RATE,
            "duration_s": (STEPS - 1) / RATE,
            "recording_id": "validate-clean",
            "title": "clean recording for the rule tests",
            "acquisition": {
                "platform": "drone, 4K camera (synthetic)",
                "sensors": [{"id": "cam", "kind": "rgb_camera", "rate_hz": RATE}],
                "not_observable": ["light_", "interior"],
                "site": {"name": "test site", "country": "DE", "road_type": "motorway",
                         "selection_reason": "tests"},
            },
            "coverage": "POLYGON ((0 -12, 1000 -12, 1000 2, 0 2, 0 -12))",
            "rights": {"right_of_use": "research_only", "license": "CC-BY-4.0",
                       "owner": "Test Institute"},
            "source": {"converter": "tests", "converter_version": "1"},
        },
    }


def fresh() -> dict:
    return copy.deepcopy(_BASE)


def build(sc: dict):
    """A Recording from a scene."""
    tr = sc["tracks"]
    lens = [len(t["time"]) for t in tr]
    ids = sc.get("track_ids") or list(range(len(tr)))
    states = {"participant_id": np.repeat(np.asarray(ids, np.int64), lens)}
    for c in ("time", "x", "y", "heading", "vx", "vy"):
        states[c] = np.concatenate([t[c] for t in tr])
    n = len(states["time"])
    for c, v in sc["std"].items():
        states[c] = np.full(n, v) if np.isscalar(v) else np.asarray(v)
    for c, v in sc["extra_states"].items():
        states[c] = v
    # build_recording wants (participant_id, time) order
    order = np.lexsort((states["time"], states["participant_id"]))
    states = {k: (np.asarray(v)[order] if not isinstance(v, pa.Array) else v.take(pa.array(order)))
              for k, v in states.items()}
    meta = dict(sc["meta"])
    crs = meta.pop("crs")
    part = dict(sc["participants"])
    if isinstance(part.get("class_pmf"), np.ndarray):
        part["class_pmf"] = pmf_array(part["class_pmf"], "class", sc.get("pmf_null"))
    return build_recording(map_source=sc["map"], participants=part, states=states,
                           unobserved=sc["unobserved"], events=sc["events"], crs=crs, **meta)


_BASE = scene()


def set_column(rec, table: str, name: str, values) -> None:
    """Replace (or add) a column of a built recording's table."""
    t = rec.table(table)
    arr = values if isinstance(values, (pa.Array, pa.ChunkedArray)) else pa.array(values)
    if name in t.column_names:
        t = t.set_column(t.column_names.index(name), name, arr)
    else:
        t = t.append_column(name, arr)
    rec.replace_tables({table: t})


def column(rec, table: str, name: str) -> np.ndarray:
    return rec.table(table).column(name).to_numpy(zero_copy_only=False).copy()


def row_of(rec, pid: int, k: int) -> int:
    """File row of participant pid's k-th sample."""
    p = column(rec, "states", "participant_id")
    return int(np.flatnonzero(p == pid)[k])


def table_from_spec(name: str, n: int) -> pa.Table:
    """A table of n rows with every declared column of ``name`` filled with zeros / defaults."""
    from aveas_format.io.arrow import arrow_type

    cols = {}
    for c in TABLES[name].columns:
        typ = arrow_type(c)
        if c.name == "participant_id":
            cols[c.name] = pa.array(np.zeros(n, np.int64))
        elif c.name == "time":
            cols[c.name] = pa.array(np.arange(n) / RATE)
        elif pa.types.is_floating(typ):
            cols[c.name] = pa.array(np.zeros(n), typ)
        else:
            continue
    return pa.table(cols)
