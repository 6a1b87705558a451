"""Small recordings with given motion for the derivation tests."""

from __future__ import annotations

import json

import numpy as np

from aveas_format.mapref.build import build_recording
from aveas_format.opendrive.builder import straight_highway
from aveas_format.sample import SITE_CRS

from helpers_common import shared


def vectors() -> dict:
    """The analytic criticality cases of ../shared/data/criticality/vectors.json (for a realdata
    test; skips without ../shared)."""
    return {v["id"]: v for v in json.loads(shared("data", "criticality", "vectors.json").read_text())["vectors"]}


def value(v):
    return np.inf if v == "inf" else float(v)


def road_map(hdg: float = 0.0, x0: float = 0.0, y0: float = 0.0, length: float = 1000.0) -> str:
    return straight_highway(length=length, lanes_right=3, x0=x0, y0=y0, hdg=hdg,
                            geo_reference=SITE_CRS)


def recording(actors: list[dict], *, duration: float = 1.0, dt: float = 0.04,
              xodr: str | None = None, rotate: float = 0.0, shift=(0.0, 0.0),
              pos_std: float = 0.1, measured_accel: bool = True, **kw):
    """A recording of actors moving with constant acceleration in the plane.

    Each actor: x, y, heading (rad), length, width, vx, vy and optional ax, ay. The whole scene
    (and the map, when ``xodr`` is None) is rotated by ``rotate`` about the origin and then
    shifted by ``shift``."""
    t = np.arange(int(round(duration / dt)) + 1) * dt
    c, s = np.cos(rotate), np.sin(rotate)
    cols: dict[str, list] = {k: [] for k in ("participant_id", "time", "x", "y", "heading", "vx",
                                             "vy", "ax", "ay")}
    for i, a in enumerate(actors):
        ax, ay = a.get("ax", 0.0), a.get("ay", 0.0)
        x = a["x"] + a["vx"] * t + 0.5 * ax * t * t
        y = a["y"] + a["vy"] * t + 0.5 * ay * t * t
        vx, vy = a["vx"] + ax * t, a["vy"] + ay * t
        cols["participant_id"].append(np.full(len(t), i))
        cols["time"].append(t)
        cols["x"].append(c * x - s * y + shift[0])
        cols["y"].append(s * x + c * y + shift[1])
        cols["heading"].append(np.full(len(t), a.get("heading", 0.0) + rotate))
        cols["vx"].append(c * vx - s * vy)
        cols["vy"].append(s * vx + c * vy)
        cols["ax"].append(np.full(len(t), c * ax - s * ay))
        cols["ay"].append(np.full(len(t), s * ax + c * ay))
    states = {k: np.concatenate(v) for k, v in cols.items()}
    if not measured_accel:
        del states["ax"], states["ay"]
    n = len(states["time"])
    states["heading"] = np.angle(np.exp(1j * states["heading"]))
    for k in ("x_std", "y_std"):
        states[k] = np.full(n, pos_std)
    for k in ("vx_std", "vy_std"):
        states[k] = np.full(n, 0.1)
    states["heading_std"] = np.full(n, 0.01)
    m = len(actors)
    participants = {"participant_id": np.arange(m), "class": ["car"] * m,
                    "length": np.array([a["length"] for a in actors], float),
                    "width": np.array([a["width"] for a in actors], float),
                    "length_std": np.full(m, 0.05), "width_std": np.full(m, 0.05)}
    if xodr is None:
        xodr = road_map(hdg=rotate, x0=shift[0], y0=shift[1])
    kw.setdefault("method", "aerial")
    kw.setdefault("partner", "test")
    return build_recording(map_source=xodr, participants=participants, states=states, **kw)


def row(table, **where):
    """The rows of a pyarrow table matching column == value (approximately for floats)."""
    d = table.to_pylist()
    out = []
    for r in d:
        if all((abs(r[k] - v) < 1e-9) if isinstance(v, float) else (str(r[k]) == str(v))
               for k, v in where.items()):
            out.append(r)
    return out
