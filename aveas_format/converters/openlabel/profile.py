"""The AVEAS OpenLABEL profile, shared by both directions: what maps to what, and the encodings.

- the mapping tables: format class <-> object type (``CLASS_TO_TYPE``; the types of generic files:
  the one label table, :mod:`aveas_format.converters.labels`), event kinds, acquisition methods, lights, lighting and road-surface categories;
  which states and participants columns the profile's attributes carry (the rest goes into the
  ``aveas_format`` extension, ``EXT``);
- conditions <-> environment-context attributes (PMF vectors, Beaufort force), both ways;
- the profile's ``acquisition_date`` format, enum values as ``aveas-openlabel`` writes them;
- attribute lookup in an OpenLABEL ``object_data``/``context_data`` (``attributes_of``, ``first_value``).
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from aveas_format.schema.taxonomy import LIGHTING, ROAD_SURFACE

#: the namespace of everything this library adds to an OpenLABEL file
EXT = "aveas_format"
EXT_VERSION = "1"

#: format class -> AVEAS OpenLABEL object type (same 13 classes, same order)
CLASS_TO_TYPE: dict[str, str] = {
    "animal": "animal", "bicycle": "vehicle/bicycle", "bus": "vehicle/bus", "car": "vehicle/car",
    "pedestrian": "human/pedestrian", "mobility_device": "vehicle/mobility_device",
    "motorcycle": "vehicle/motorcycle", "other": "other", "pushable_pullable": "pushable_pullable",
    "railvehicle": "vehicle/railvehicle", "trailer": "vehicle/trailer", "truck": "vehicle/truck",
    "van": "vehicle/van",
}
TYPE_TO_CLASS = {v: k for k, v in CLASS_TO_TYPE.items()}
#: classes without ``is_recorder`` in the profile
NO_RECORDER = {"animal", "pushable_pullable", "trailer"}
#: classes whose frames carry the mandatory road attributes in the profile
ROAD_CLASSES = {"bicycle", "bus", "car", "mobility_device", "motorcycle", "other", "railvehicle",
                 "trailer", "truck", "van"}
#: the attributes every object in a frame carries in the profile (its ``velocity`` and
#: ``acceleration`` are mandatory); a file that claims the profile (its metadata or object types)
#: and lacks one is reported (``source.openlabel.missing_attribute``)
MANDATORY_FRAME_ATTRIBUTES = ("velocity", "acceleration")
#: the attributes every object carries in the profile
MANDATORY_OBJECT_ATTRIBUTES = ("dimensions/size",)
#: format event kinds <-> AVEAS event types
EVENT_TO_TYPE = {"lane_change": "lane change", "parking": "parking", "turning": "turning",
                 "overtaking": "overtaking", "following": "following"}
TYPE_TO_EVENT = {v: k for k, v in EVENT_TO_TYPE.items()}
#: acquisition methods (format -> profile); the exact method is kept in the extension
METHOD_TO_PROFILE = {
    "aerial": "aerial", "traffic_simulation": "aerial", "accident_reconstruction": "aerial",
    "infrastructure_lidar": "stationary", "infrastructure_lwir": "stationary",
    "infrastructure_camera": "stationary", "road_vehicle": "in-vehicle",
    "driving_simulator": "in-vehicle",
}
PROFILE_TO_METHOD = {"aerial": "aerial", "stationary": "infrastructure_camera",
                     "in-vehicle": "road_vehicle"}
#: lights: format column -> profile boolean attribute
LIGHTS = {
    "light_brake_p": "lights/brake", "light_indicator_left_p": "lights/indicator/left",
    "light_indicator_right_p": "lights/indicator/right", "light_front_p": "lights/front",
    "light_high_beam_p": "lights/high_beam",
}
LONGITUDINAL = "interior/automated_control/longitudinal"
#: the attributes of an object in a frame that the import reads, declared once: name -> (shape,
#: column or {column: element}). A ``vector``'s elements go to their columns (a column named like
#: a states column is that column, else the import turns it into one: vehicle -> world frame);
#: ``number`` a float, ``text`` the value, ``flag`` 0/1 (NaN where absent) into its column.
#: Adding an attribute that is a states column is this one line (the export writes its own).
FRAME_ATTRIBUTES: dict[str, tuple[str, str | dict[str, int]]] = {
    "velocity": ("vector", {"vu": 0, "vv": 1, "yaw_rate": 5}),
    "acceleration": ("vector", {"au": 0, "av": 1}),
    "velocity/ustddev": ("vector", {"vu_std": 0, "vv_std": 1, "yaw_rate_std": 5}),
    "acceleration/ustddev": ("vector", {"au_std": 0, "av_std": 1}),
    "bounding_box/ustddev": ("vector", {"x_std": 0, "y_std": 1, "z_std": 2, "heading_std": 5}),
    "open_drive/local_road_coordinates": ("vector", {"road_s": 0, "road_t": 1}),
    "open_drive/lane_position": ("number", "lane_position"),
    "used_road_link": ("text", "road_link"),  # (the profile's name of the road id)
    "open_drive/road_id": ("text", "road_alt"),
    "open_drive/lane_id": ("text", "lane_code"),
    **{name: ("flag", column) for column, name in LIGHTS.items()},
}
#: the interior signals of an object in a frame (the import's interior table)
INTERIOR_ATTRIBUTES = (LONGITUDINAL, "interior/automated_control/lateral", "interior/steering_angle",
                       "interior/steering_angle/ustddev", "interior/brake_pedal", "interior/accelerator_pedal",
                       "interior/gear")
#: the attributes of an object in a frame that the profile (and this library's export) has and the
#: import does not read
UNREAD_ATTRIBUTES = ("road/classification",
                     *(f"road/number_lanes/{side}/{kind}" for side in ("left", "right") for kind in ("legal", "physical")),
                     *(f"impact/{k}/{v}" for k in ("gttc", "thw", "pret") for v in ("object_ids", "values")))
#: the attributes whose columns the import takes only where every box has a velocity (else the
#: velocities come from the positions: these would not belong to them)
VELOCITY_ATTRIBUTES = ("velocity", "velocity/ustddev", "acceleration", "acceleration/ustddev")
#: format lighting PMF <-> profile lighting_conditions (profile order: darkness, artificial,
#: civil_twilight, day)
LIGHTING_TO_PROFILE = {"day": "day", "twilight": "civil_twilight", "darkness_lit": "artificial",
                       "darkness_unlit": "darkness"}
PROFILE_LIGHTING = ("darkness", "artificial", "civil_twilight", "day")
PROFILE_ROAD = ("dry", "wet", "slippery")
_BEAUFORT = (0.5, 1.5, 3.3, 5.5, 7.9, 10.7, 13.8, 17.1, 20.7, 24.4, 28.4, 32.6)  # upper m/s bounds
DEFAULT_THRESHOLDS = {"ttc_s": 3.0, "pet_s": 1.5, "thw_s": 1.0}

#: states columns the profile attributes carry (possibly as a placeholder where null)
PROFILE_STATE_COLS = {"participant_id", "time", "x", "y", "z", "heading", "vx", "vy", "ax", "ay",
                       "yaw_rate", "lon", "lat", "road_id", "lane_id", "road_s", "road_t",
                       "x_std", "y_std", "z_std", "heading_std"}
PROFILE_PART_COLS = {"participant_id", "source_id", "class", "class_pmf", "length", "width",
                      "height", "length_std", "width_std", "height_std", "attached_to"}


# ================================================================================================
# helpers
# ================================================================================================

def iso_ms(ts: str) -> str:
    """recording start_time -> the profile's yyyy-MM-ddTHH:mm:ss.FFFZ."""
    m = re.match(r"^(\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2})(?:\.(\d+))?Z$", ts)
    if not m:
        return ts
    return f"{m[1]}.{(m[2] or '').ljust(3, '0')[:3]}Z"


def enum_value(v: Any) -> Any:
    """aveas-openlabel writes str enums as ``"Road__ClassificationValue.STRAIGHT"``: -> "straight"."""
    if isinstance(v, str) and "." in v:
        head, tail = v.split(".", 1)
        if head.endswith("Value") and re.fullmatch(r"[A-Z0-9_]+", tail):
            return tail.lower()
    return v


def _beaufort(speed: float) -> int:
    return int(np.searchsorted(np.asarray(_BEAUFORT), speed, side="right"))


def _beaufort_speed(force: float) -> float:
    edges = (0.0,) + _BEAUFORT + (36.0,)
    k = int(min(max(round(force), 0), 12))
    return round(0.5 * (edges[k] + edges[k + 1]), 2)


# ================================================================================================
# attributes of object_data / context_data
# ================================================================================================

def object_type(objects: Any, uid: str, frame_types: dict[str, str]) -> str:
    """An object's type: in ``objects``, else inside its ``object_data`` (TUM Traffic), else the one
    given inside a frame (``frame_types``), else ``other``."""
    obj = objects.get(uid) if isinstance(objects, dict) and isinstance(objects.get(uid), dict) else {}
    od = obj.get("object_data") if isinstance(obj.get("object_data"), dict) else {}
    return str(obj.get("type") or (od.get("type") if isinstance(od.get("type"), str) else None)
               or frame_types.get(uid) or "other")


def attributes_of(od: dict[str, Any] | None) -> dict[str, list[dict[str, Any]]]:
    """name -> list of items (all types), in file order (on the import's hot path: one call per box)."""
    out: dict[str, list] = {}
    if not od:
        return out
    for kind in ("boolean", "num", "text", "vec"):
        items = od.get(kind)
        if not items:
            continue
        if isinstance(items, dict):
            items = [items]
        for it in items:
            if isinstance(it, dict) and "name" in it:
                name = it["name"]
                same = out.get(name)
                if same is None:
                    out[name] = [it]
                else:
                    same.append(it)
    return out


def first_value(attrs, name, default=None):
    items = attrs.get(name)
    return items[0].get("val", default) if items else default


def pmf_bad(v: Any) -> bool:
    """Whether a PMF value is no vector of numbers summing to 1 (within the schema's tolerance)."""
    from aveas_format.schema.pmf import pmf_problems

    try:
        m = np.asarray([v], float)
    except (TypeError, ValueError):
        return True
    return m.ndim != 2 or bool(pmf_problems(m)[0])


# ================================================================================================
# conditions <-> environment contexts
# ================================================================================================

def _pmf_vector(pmf: dict | None, cats: tuple[str, ...], mapping: dict[str, str],
                out_cats: tuple[str, ...]) -> list[float] | None:
    if not pmf:
        return None
    vals = dict.fromkeys(out_cats, 0.0)
    for c in cats:
        vals[mapping[c]] += float(pmf.get(c, 0.0) or 0.0)
    tot = sum(vals.values())
    return [v / tot for v in vals.values()] if tot > 0 else None


def _rounded(v: float) -> int:
    return int(round(v))


#: conditions <-> the environment context's numbers: (key, attribute, to the profile, from it)
_ENV_NUMBERS = (
    ("temperature_c", "environment/temperature_celsius", _rounded, float),
    ("temperature_c_std", "environment/temperature/ustddev", float, float),
    ("precipitation_mm_h", "environment/precipitation_intensity", _rounded, float),
    ("visibility_m", "environment/visibility_range", _rounded, float),
    ("cloud_cover_okta", "environment/cloud_cover", int, lambda v: int(v) if 0 <= int(v) <= 8 else None),
    ("wind_speed_m_s", "environment/wind/beaufort_force", _beaufort, lambda v: _beaufort_speed(float(v))))


def environment_data(cond: dict[str, Any]) -> dict[str, list]:
    data: dict[str, list] = {"num": [], "text": [], "vec": []}
    lighting = _pmf_vector(cond.get("lighting"), LIGHTING, LIGHTING_TO_PROFILE, PROFILE_LIGHTING)
    if lighting:
        data["text"].append({"name": "lighting_conditions",
                             "val": PROFILE_LIGHTING[int(np.argmax(lighting))]})
        data["vec"].append({"name": "environment/lighting_conditions/uncertainties", "val": lighting})
    road = _pmf_vector(cond.get("road_surface"), ROAD_SURFACE,
                       {"dry": "dry", "wet": "wet", "slippery": "slippery", "snow_ice": "slippery"},
                       PROFILE_ROAD)
    if road:
        data["text"].append({"name": "road_condition", "val": PROFILE_ROAD[int(np.argmax(road))]})
        data["vec"].append({"name": "environment/road_condition/uncertainties", "val": road})
    for key, name, to_profile, _ in _ENV_NUMBERS:
        if cond.get(key) is not None:
            data["num"].append({"name": name, "val": to_profile(cond[key])})
    return data


def conditions_from(cd: dict[str, Any]) -> dict[str, Any]:
    a = attributes_of(cd)
    out: dict[str, Any] = {}
    lu = first_value(a, "environment/lighting_conditions/uncertainties")
    lv = enum_value(first_value(a, "lighting_conditions"))
    inv = {v: k for k, v in LIGHTING_TO_PROFILE.items()}
    if lu and len(lu) == 4:
        out["lighting"] = {inv[c]: float(v) for c, v in zip(PROFILE_LIGHTING, lu)}
    elif lv in inv:
        out["lighting"] = {inv[lv]: 1.0}
    ru = first_value(a, "environment/road_condition/uncertainties")
    rv = enum_value(first_value(a, "road_condition"))
    if ru and len(ru) == 3:
        out["road_surface"] = {c: float(v) for c, v in zip(PROFILE_ROAD, ru)}
    elif rv in PROFILE_ROAD:
        out["road_surface"] = {rv: 1.0}
    for key, name, _, from_profile in _ENV_NUMBERS:
        v = first_value(a, name)
        if v is not None and from_profile(v) is not None:
            out[key] = from_profile(v)
    return out
