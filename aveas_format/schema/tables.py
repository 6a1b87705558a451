"""The tables of a recording, declared column by column (FORMAT.md sections 4-10).

``TABLES`` maps a table name to its :class:`~aveas_format.schema.columns.TableSpec`. Core tables are
named after their file (``states`` -> ``states.parquet``) and declared here; derived tables are named
``derived/NAME`` (-> ``derived/NAME.parquet``) and declared by the derivation that writes them
(``aveas_format/derive/NAME.py``, or a partner package's), which registers the spec here through
:func:`register_table` (via ``derive.registry.register``). recording.json's ``tables`` uses the same
names.

``TABLES`` loads the derivations (:func:`aveas_format.plugins.load`) the first time it is asked for a
derived table it does not know yet, or for the list of every table: ``io`` and ``validate`` find the
derived specs without importing ``derive`` (docs/extending.md).
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Mapping

from aveas_format import plugins
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
    interval_cols,
    pid_col,
    pmf,
    prob,
    std_of,
    time_col,
)
from aveas_format.schema.enums import (
    EventKind,
    EventOrigin,
    Provenance,
    Role,
    UnobservedKind,
)
from aveas_format.schema.taxonomy import CLASSES

PI = 3.141592653589793
MEASURED = "measured"  # condition: provenance natural or staged


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
        pid_col(),
        time_col(),
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
        *interval_cols(),
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
    doc="Labelled or derived events (near misses, conflicts, lane changes, ...). A near miss is a "
    "scenario in which an accident was averted predominantly due to stochastic effects; a "
    "conflict one in which road users came so close that they would have collided had they kept "
    "their motion, and the recorded behaviour averted it.",
    key=("event_id",),
    sort=("event_id",),
    columns=(
        col("event_id", "int64", MUST, "event id, unique", minimum=0, nullable=False),
        enum_col("kind", EventKind.values(), MUST, "kind of event", nullable=False),
        *interval_cols(),
        col("participant_ids", "list<int64>", MUST, "participants involved", nullable=False),
        col("roles", "list<string>", MAY, "role of each participant in the event (same length as "
            "participant_ids)"),
        col("confidence", "float32", MAY, "confidence that the event happened", minimum=0.0,
            maximum=1.0),
        enum_col("origin", EventOrigin.values(), MUST, "annotated by a person or derived by a method",
                 nullable=False),
        col("attributes", "string", MAY, "JSON object: metric and threshold for derived events, ..."),
        col("metric", "string", MAY, "the measure that found a derived event: ttc, pet, drac "
            "or a_lon"),
        col("relation", "string", MAY, "how the participants of a derived event relate at its "
            "extreme: leader, left_neighbour, right_neighbour, conflicting (derived/interactions) "
            "or crossing (an encroachment)"),
        *gaussian("value", None, MAY, "the extreme value of `metric` in the event, in its unit "
                  "(s for ttc and pet, m/s² for drac and a_lon)"),
        col("time_extreme", "float64", MAY, "time of `value`", "s"),
        col("duration", "float64", MAY, "observed time in which the measure was beyond its "
            "threshold (the sampling intervals of its steps)", "s", minimum=0.0),
        *gaussian("collision_probability", None, MAY, "probability that the participants touch "
                  "under variations of the recorded encounter within its stated uncertainty "
                  "(docs/derive.md)", minimum=0.0, maximum=1.0),
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
        *interval_cols(),
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
        pid_col(),
        time_col(),
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

CORE_TABLES: tuple[TableSpec, ...] = (PARTICIPANTS, STATES, UNOBSERVED, EVENTS, ENVIRONMENT, INTERIOR)

DERIVED_PREFIX = "derived/"


class TableRegistry(Mapping[str, TableSpec]):
    """Every table of the format by name: the core tables in their declared order, then the derived
    tables by name. Looking up an unknown ``derived/NAME``, or listing the tables, first loads the
    derivations (built-in and plugins), whose modules register the derived specs."""

    def __init__(self, core: tuple[TableSpec, ...]) -> None:
        self._core = {t.name: t for t in core}
        self._derived: dict[str, TableSpec] = {}

    def register(self, spec: TableSpec) -> TableSpec:
        """Add the spec of a derived table (its name must be new)."""
        name = spec.name
        short = name.removeprefix(DERIVED_PREFIX)
        if not (spec.derived and name.startswith(DERIVED_PREFIX) and short and "/" not in short
                and spec.file == f"{name}.parquet"):
            raise ValueError(f"table {name!r}: a derived table is named derived/NAME, stored in "
                             "derived/NAME.parquet and declared with derived=True (derived_table())")
        if name in self._core or name in self._derived:
            raise ValueError(f"table {name!r} is declared twice")
        self._derived[name] = spec
        return spec

    def unregister(self, name: str) -> None:
        """Remove a derived table (tests that register one of their own)."""
        del self._derived[name]

    def _load(self) -> None:
        plugins.load("derivations")

    def order(self, names: Iterable[str]) -> list[str]:
        """Known ``names`` in the registry's order, without loading the derivations unless one
        of them names a derived table (``io`` reading a recording of core tables only)."""
        rank = {n: i for i, n in enumerate(self._core)}  # derived tables after them, by name
        return sorted({n for n in names if n in self}, key=lambda n: (rank.get(n, len(rank)), n))

    def __getitem__(self, name: str) -> TableSpec:
        spec = self._core.get(name)
        if spec is None:
            spec = self._derived.get(name)
        if spec is None and name.startswith(DERIVED_PREFIX):
            self._load()
            spec = self._derived.get(name)
        if spec is None:
            raise KeyError(name)
        return spec

    def __iter__(self) -> Iterator[str]:
        self._load()
        return iter([*self._core, *sorted(self._derived)])

    def __len__(self) -> int:
        self._load()
        return len(self._core) + len(self._derived)

    def __repr__(self) -> str:
        return f"TableRegistry({list(self)})"


TABLES = TableRegistry(CORE_TABLES)


def derived_table(name: str, doc: str, columns: Iterable[Column], *, key: tuple[str, ...] = (),
                  sort: tuple[str, ...] = ()) -> TableSpec:
    """The spec of the derived table ``derived/NAME`` (FORMAT.md 10: optional, stored in
    ``derived/NAME.parquet``); a derivation passes it as ``Derivation(spec=...)``."""
    return TableSpec(name=f"{DERIVED_PREFIX}{name}", file=f"{DERIVED_PREFIX}{name}.parquet",
                     requirement=MAY, derived=True, doc=doc, key=key, sort=sort,
                     columns=tuple(columns))


def register_table(spec: TableSpec) -> TableSpec:
    """Register the spec of a derived table in :data:`TABLES` (``derive.registry.register`` does
    it for the table a derivation declares)."""
    return TABLES.register(spec)


def derived_tables() -> tuple[TableSpec, ...]:
    """Every derived table, by name (loads the derivations)."""
    return tuple(TABLES[n] for n in TABLES if n.startswith(DERIVED_PREFIX))


def table_spec(name: str) -> TableSpec:
    """The spec of a table by name (``states``, ``derived/kinematics``...); KeyError if unknown."""
    return TABLES[name]


def tables_spec() -> dict[str, object]:
    """The machine-readable spec of every table (``aveas-format schema --tables``)."""
    from aveas_format.schema.versions import FORMAT_VERSION

    return {"format_version": FORMAT_VERSION, "tables": [t.to_spec() for t in TABLES.values()]}
