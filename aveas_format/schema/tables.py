"""The tables of a recording, declared column by column (FORMAT.md sections 4-10).

``TABLES`` maps a table name to its :class:`~aveas_format.schema.columns.TableSpec`. Core tables are
named after their file (``states`` -> ``states.parquet``); derived tables are named ``derived/NAME``
(-> ``derived/NAME.parquet``), and recording.json's ``tables`` uses the same names.
"""

from __future__ import annotations

from aveas_format.schema.columns import (
    MAY,
    MUST,
    SHOULD,
    Column,
    TableSpec,
    col,
    corr,
    enum_col,
    gaussian,
    pmf,
    prob,
    std_of,
)
from aveas_format.schema.enums import (
    EventKind,
    EventOrigin,
    Provenance,
    Relation,
    Role,
    TtcKind,
    UnobservedKind,
)
from aveas_format.schema.taxonomy import CLASSES

PI = 3.141592653589793
MEASURED = "measured"  # condition: provenance natural or staged


def _pid(doc: str = "participant, refers to participants.participant_id") -> Column:
    return col("participant_id", "int64", MUST, doc, minimum=0, nullable=False)


def _time(doc: str = "seconds since recording.json:start_time") -> Column:
    return col("time", "float64", MUST, doc, "s", nullable=False)


def _interval(req=MUST) -> list[Column]:
    return [
        col("time_start", "float64", req, "start of the validity interval", "s", nullable=False),
        col("time_end", "float64", req, "end of the validity interval (>= time_start)", "s",
            nullable=False),
    ]


PARTICIPANTS = TableSpec(
    name="participants",
    file="participants.parquet",
    requirement=MUST,
    doc="One row per traffic participant: identity, class, size, role and provenance.",
    key=("participant_id",),
    sort=("participant_id",),
    columns=(
        col("participant_id", "int64", MUST, "unique participant id", minimum=0, nullable=False),
        col("source_id", "string", MUST, "the participant's id in the source data", nullable=False),
        enum_col("class", CLASSES, MUST, "most probable class", nullable=False),
        pmf("class_pmf", "class", SHOULD, "PMF over the 13 classes; its argmax equals `class`",
            condition=MEASURED),
        col("length", "float64", MUST, "footprint length (along the heading)", "m", minimum=0.0,
            exclusive_minimum=True, nullable=False),
        col("width", "float64", MUST, "footprint width", "m", minimum=0.0, exclusive_minimum=True,
            nullable=False),
        col("height", "float64", MAY, "height above ground", "m", minimum=0.0, exclusive_minimum=True),
        std_of("length", "m", SHOULD, MEASURED),
        std_of("width", "m", SHOULD, MEASURED),
        std_of("height", "m", MAY),
        enum_col("role", Role.values(), MUST, "role in the recording", nullable=False),
        enum_col("provenance", Provenance.values(), MUST, "is this participant's behaviour natural, "
                 "staged or simulated", nullable=False),
        col("attached_to", "int64", MAY, "participant this one is attached to (a trailer's towing "
            "vehicle)", minimum=0),
        col("attributes", "string", MAY, "further static attributes as a JSON object (operator age, "
            "mass, axles, ...)"),
    ),
)

STATES = TableSpec(
    name="states",
    file="states.parquet",
    requirement=MUST,
    doc="One row per participant and time: the map-referenced trajectory with its uncertainty.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(
        _pid(),
        _time(),
        *gaussian("x", "m", MUST, "reference point (footprint centre), local frame", nullable=False,
                  std_req=SHOULD, std_condition=MEASURED),
        *gaussian("y", "m", MUST, "reference point (footprint centre), local frame", nullable=False,
                  std_req=SHOULD, std_condition=MEASURED),
        *gaussian("z", "m", MAY, "reference point height (ground level), local frame"),
        *gaussian("heading", "rad", MUST, "body orientation, counter-clockwise from +x",
                  minimum=-PI, maximum=PI, nullable=False, std_req=SHOULD, std_condition=MEASURED),
        *gaussian("vx", "m/s", MUST, "velocity x, local frame", nullable=False, std_req=SHOULD,
                  std_condition=MEASURED),
        *gaussian("vy", "m/s", MUST, "velocity y, local frame", nullable=False, std_req=SHOULD,
                  std_condition=MEASURED),
        corr("xy_corr", "x", "y"),
        corr("vxvy_corr", "vx", "vy"),
        col("lon", "float64", MUST, "WGS 84 longitude of the reference point", "deg",
            minimum=-180.0, maximum=180.0, nullable=False),
        col("lat", "float64", MUST, "WGS 84 latitude of the reference point", "deg",
            minimum=-90.0, maximum=90.0, nullable=False),
        col("road_id", "dict<string>", MUST, "OpenDRIVE road; null where off-map"),
        col("lane_id", "int16", MUST, "OpenDRIVE lane (left > 0, right < 0); null where off-map"),
        col("road_s", "float64", MUST, "distance along the road's reference line; null where off-map",
            "m", minimum=0.0),
        col("road_t", "float64", MUST, "lateral offset from the reference line, positive to the left; "
            "null where off-map", "m"),
        col("lane_offset", "float64", MAY, "lateral offset from the lane centre line, positive to the "
            "left (high-resolution lateral position)", "m"),
        *gaussian("ax", "m/s²", MAY, "measured acceleration x, local frame"),
        *gaussian("ay", "m/s²", MAY, "measured acceleration y, local frame"),
        corr("axay_corr", "ax", "ay"),
        *gaussian("yaw_rate", "rad/s", MAY, "yaw rate, counter-clockwise positive"),
        prob("light_brake_p", "the brake light is on"),
        prob("light_indicator_left_p", "the left indicator is on"),
        prob("light_indicator_right_p", "the right indicator is on"),
        prob("light_hazard_p", "the hazard lights are on"),
        prob("light_reverse_p", "the reversing light is on"),
        prob("light_front_p", "the front lights are on"),
        prob("light_high_beam_p", "the high beam is on"),
        col("visible_fraction", "float32", MAY, "share of the footprint visible to the sensors",
            minimum=0.0, maximum=1.0),
        col("interpolated", "bool", MAY, "true where the sample was filled in, not measured"),
        col("source_frame", "int64", MAY, "frame number in the source"),
    ),
)

UNOBSERVED = TableSpec(
    name="unobserved",
    file="unobserved.parquet",
    requirement=SHOULD,
    doc="Regions not observed during a time interval: occlusions and sensor limits.",
    key=("region_id",),
    sort=("region_id",),
    columns=(
        col("region_id", "int64", MUST, "region id, unique", minimum=0, nullable=False),
        *_interval(),
        enum_col("kind", UnobservedKind.values(), MUST, "why the region was not observed",
                 nullable=False),
        col("geometry", "binary", MUST, "WKB Polygon or MultiPolygon, local frame", nullable=False),
        col("sensor_id", "string", MAY, "sensor (recording.json acquisition.sensors id)"),
        col("occluder_id", "int64", MAY, "participant causing the occlusion", minimum=0),
    ),
)

EVENTS = TableSpec(
    name="events",
    file="events.parquet",
    requirement=MAY,
    doc="Labelled or derived events (near misses, lane changes, ...). A near miss is a scenario in "
    "which an accident was averted predominantly due to stochastic effects.",
    key=("event_id",),
    sort=("event_id",),
    columns=(
        col("event_id", "int64", MUST, "event id, unique", minimum=0, nullable=False),
        enum_col("kind", EventKind.values(), MUST, "kind of event", nullable=False),
        *_interval(),
        col("participant_ids", "list<int64>", MUST, "participants involved", nullable=False),
        col("roles", "list<string>", MAY, "role of each participant in the event (same length as "
            "participant_ids)"),
        col("confidence", "float32", MAY, "confidence that the event happened", minimum=0.0,
            maximum=1.0),
        enum_col("origin", EventOrigin.values(), MUST, "annotated by a person or derived by a method",
                 nullable=False),
        col("attributes", "string", MAY, "JSON object: metric and threshold for derived events, ..."),
    ),
)

ENVIRONMENT = TableSpec(
    name="environment",
    file="environment.parquet",
    requirement=MAY,
    doc="Environment conditions that change during the recording (the static ones live in "
    "recording.json `conditions`).",
    key=("time_start",),
    sort=("time_start",),
    columns=(
        *_interval(),
        pmf("weather", "weather", MAY, "weather"),
        pmf("lighting", "lighting", MAY, "lighting"),
        pmf("road_surface", "road_surface", MAY, "road surface"),
        *gaussian("temperature_c", "°C", MAY, "air temperature"),
        col("precipitation_mm_h", "float64", MAY, "precipitation rate", "mm/h", minimum=0.0),
        col("visibility_m", "float64", MAY, "meteorological visibility", "m", minimum=0.0),
        col("wind_speed_m_s", "float64", MAY, "wind speed", "m/s", minimum=0.0),
        col("cloud_cover_okta", "int8", MAY, "cloud cover", "okta", minimum=0, maximum=8),
    ),
)

INTERIOR = TableSpec(
    name="interior",
    file="interior.parquet",
    requirement=MAY,
    doc="In-vehicle and driver data of the recording vehicle, the system under test or a "
    "driving-simulator subject.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(
        _pid(),
        _time(),
        *gaussian("steering_angle", "rad", MAY, "road-wheel steering angle, left positive"),
        *gaussian("steering_wheel_angle", "rad", MAY, "steering-wheel angle, left positive"),
        *gaussian("accelerator_pedal", None, MAY, "accelerator pedal position", minimum=0.0,
                  maximum=1.0),
        *gaussian("brake_pedal", None, MAY, "brake pedal position", minimum=0.0, maximum=1.0),
        col("gear", "int8", MAY, "gear (negative = reverse, 0 = neutral/park)"),
        prob("automation_longitudinal_p", "longitudinal automation is engaged"),
        prob("automation_lateral_p", "lateral automation is engaged"),
        prob("takeover_request_p", "the system requests a takeover"),
        *gaussian("driver_head_yaw", "rad", MAY, "driver head yaw, vehicle frame"),
        *gaussian("driver_head_pitch", "rad", MAY, "driver head pitch, vehicle frame"),
        *gaussian("driver_head_roll", "rad", MAY, "driver head roll, vehicle frame"),
        *gaussian("driver_gaze_yaw", "rad", MAY, "driver gaze yaw, vehicle frame"),
        *gaussian("driver_gaze_pitch", "rad", MAY, "driver gaze pitch, vehicle frame"),
        prob("hands_on_wheel_p", "the driver's hands are on the wheel"),
        pmf("driver_focus", "driver_focus", MAY, "where the driver's attention is"),
    ),
)

# --- derived tables (FORMAT.md section 10) -----------------------------------------------------

KINEMATICS = TableSpec(
    name="derived/kinematics",
    file="derived/kinematics.parquet",
    requirement=MAY,
    derived=True,
    doc="Speed, accelerations and jerk per participant and time, estimated from the positions with "
    "their uncertainty.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(
        _pid(),
        _time(),
        *gaussian("speed", "m/s", MUST, "speed over ground", minimum=0.0, std_req=MUST),
        *gaussian("ax", "m/s²", MUST, "acceleration x, local frame", std_req=MUST),
        *gaussian("ay", "m/s²", MUST, "acceleration y, local frame", std_req=MUST),
        *gaussian("a_lon", "m/s²", MUST, "longitudinal acceleration (along the heading)",
                  std_req=MUST),
        *gaussian("a_lat", "m/s²", MUST, "lateral acceleration (to the left of the heading)",
                  std_req=MUST),
        *gaussian("jerk_lon", "m/s³", MUST, "longitudinal jerk", std_req=MUST),
    ),
)

INTERACTIONS = TableSpec(
    name="derived/interactions",
    file="derived/interactions.parquet",
    requirement=MAY,
    derived=True,
    doc="Pairwise relations per time step: leaders, followers, neighbours and conflicting "
    "participants with time to collision and headways.",
    key=("participant_id", "time", "other_id", "relation"),
    sort=("participant_id", "time", "other_id"),
    columns=(
        _pid(),
        _time(),
        col("other_id", "int64", MUST, "the other participant", minimum=0, nullable=False),
        enum_col("relation", Relation.values(), MUST, "relation of `other_id` to `participant_id`",
                 nullable=False),
        *gaussian("ttc", "s", MAY, "time to collision (null = no collision course)", minimum=0.0),
        enum_col("ttc_kind", TtcKind.values(), MAY, "how `ttc` was computed"),
        *gaussian("ttc_ca", "s", MAY, "time to collision with constant accelerations (vehicles stop "
                  "rather than reverse; null = no collision)", minimum=0.0),
        *gaussian("gap", "m", MAY, "net bumper-to-bumper gap"),
        col("thw", "float64", MAY, "time headway: net gap / speed of the follower (null = infinite)",
            "s", minimum=0.0),
        col("dhw", "float64", MAY, "distance headway: gross front-to-front spacing (gap + leader "
            "length); in left/right_neighbour rows the signed front-to-front distance along the "
            "lane (>= 0: the neighbour leads, < 0: it lags)", "m"),
        col("closing_speed", "float64", MAY, "rate at which the gap closes (positive = closing)",
            "m/s"),
    ),
)

ENCROACHMENTS = TableSpec(
    name="derived/encroachments",
    file="derived/encroachments.parquet",
    requirement=MAY,
    derived=True,
    doc="Post-encroachment times: one row per pair of participants passing through a common "
    "conflict area.",
    key=("conflict_id",),
    sort=("conflict_id",),
    columns=(
        col("conflict_id", "int64", MUST, "conflict id, unique", minimum=0, nullable=False),
        col("first_id", "int64", MUST, "participant that leaves the conflict area first", minimum=0,
            nullable=False),
        col("second_id", "int64", MUST, "participant that enters it second", minimum=0,
            nullable=False),
        col("time_first_exit", "float64", MUST, "time the first participant leaves the area", "s"),
        col("time_second_enter", "float64", MUST, "time the second participant enters the area", "s"),
        *gaussian("pet", "s", MUST, "post-encroachment time", minimum=0.0),
        col("geometry", "binary", MUST, "conflict area, WKB polygon, local frame"),
    ),
)

TRAFFIC = TableSpec(
    name="derived/traffic",
    file="derived/traffic.parquet",
    requirement=MAY,
    derived=True,
    doc="Macroscopic traffic quantities per lane, road stretch and time window, after Edie's "
    "generalized definitions.",
    key=("road_id", "lane_id", "s_start", "time_start"),
    sort=("road_id", "lane_id", "s_start", "time_start"),
    columns=(
        col("road_id", "dict<string>", MUST, "OpenDRIVE road", nullable=False),
        col("lane_id", "int16", MUST, "OpenDRIVE lane", nullable=False),
        col("s_start", "float64", MUST, "start of the road stretch", "m", nullable=False),
        col("s_end", "float64", MUST, "end of the road stretch", "m", nullable=False),
        *_interval(),
        *gaussian("density", "veh/km", MUST, "density (Edie)", minimum=0.0),
        *gaussian("flow", "veh/h", MUST, "flow (Edie)", minimum=0.0),
        *gaussian("mean_speed", "m/s", MUST, "space-mean speed (flow / density)", minimum=0.0),
        col("count", "int64", MUST, "participants seen in the space-time window", minimum=0),
    ),
)

CORE_TABLES: tuple[TableSpec, ...] = (PARTICIPANTS, STATES, UNOBSERVED, EVENTS, ENVIRONMENT, INTERIOR)
DERIVED_TABLES: tuple[TableSpec, ...] = (KINEMATICS, INTERACTIONS, ENCROACHMENTS, TRAFFIC)
TABLES: dict[str, TableSpec] = {t.name: t for t in (*CORE_TABLES, *DERIVED_TABLES)}


def table_spec(name: str) -> TableSpec:
    """The spec of a table by name (``states``, ``derived/kinematics``...); KeyError if unknown."""
    return TABLES[name]


def tables_spec() -> dict[str, object]:
    """The machine-readable spec of every table (``aveas-format schema --tables``)."""
    from aveas_format.schema.versions import FORMAT_VERSION

    return {"format_version": FORMAT_VERSION, "tables": [t.to_spec() for t in TABLES.values()]}
