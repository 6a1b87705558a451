"""pydantic v2 models of ``recording.json`` (FORMAT.md section 3).

Every model is strict about keys: an unknown key is an error (free key/values belong under
``extras``). The JSON Schema of recording.json (``aveas-format schema``) is generated from
:class:`RecordingMeta`.
"""

from __future__ import annotations

import re
from datetime import datetime, timezone
from typing import Annotated, Any

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    create_model,
    field_validator,
    model_validator,
)

from aveas_format.schema.enums import (
    AcquisitionMethod,
    RecordingProvenance,
    RightOfUse,
    RoadType,
    SensorKind,
)
from aveas_format.schema.taxonomy import LIGHTING, PMF_TOLERANCE, ROAD_SURFACE, WEATHER

_SEMVER = r"^(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)$"
_SHA256 = r"^[0-9a-f]{64}$"
_ISO_UTC = re.compile(
    r"^(?P<date>\d{4}-\d{2}-\d{2})T(?P<hms>\d{2}:\d{2}:\d{2})(?:\.(?P<frac>\d{1,9}))?(?P<tz>Z|[+-]00:?00)$"
)


def _check_utc(v: str) -> str:
    m = _ISO_UTC.match(v)
    if not m:
        raise ValueError(
            "must be an ISO 8601 UTC timestamp like 2024-05-13T08:15:00Z (up to 9 fractional digits, "
            "'Z' or '+00:00')"
        )
    datetime.fromisoformat(f"{m['date']}T{m['hms']}+00:00")  # raises on 2024-13-45
    frac = f".{m['frac']}" if m["frac"] else ""
    return f"{m['date']}T{m['hms']}{frac}Z"


UtcTimestamp = Annotated[str, AfterValidator(_check_utc), Field(
    description="ISO 8601 timestamp in UTC with up to nanoseconds, e.g. 2024-05-13T08:15:00.125Z",
    json_schema_extra={"format": "date-time"},
)]


def timestamp_ns(ts: str) -> int:
    """Nanoseconds since the Unix epoch of a validated :data:`UtcTimestamp`."""
    m = _ISO_UTC.match(ts)
    if not m:
        raise ValueError(f"not a UTC timestamp: {ts!r}")
    base = datetime.fromisoformat(f"{m['date']}T{m['hms']}+00:00")
    frac = (m["frac"] or "").ljust(9, "0")
    return int(base.timestamp()) * 1_000_000_000 + int(frac or 0)


def utc_now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


_SHOULD = {"x-requirement": "SHOULD"}


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", validate_assignment=True, use_enum_values=False)


# --- PMFs --------------------------------------------------------------------------------------

class PmfModel(_Strict):
    """Base of PMF models: every field >= 0, fields sum to 1 (tolerance 1e-3)."""

    @model_validator(mode="after")
    def _normalised(self) -> PmfModel:
        total = sum(float(getattr(self, f)) for f in type(self).model_fields)
        if abs(total - 1.0) > PMF_TOLERANCE:
            raise ValueError(f"probabilities must sum to 1 (tolerance {PMF_TOLERANCE}), got {total:.6g}")
        return self

    def argmax(self) -> str:
        fields = list(type(self).model_fields)
        return max(fields, key=lambda f: getattr(self, f))

    @classmethod
    def one_hot(cls, category: str) -> PmfModel:
        if category not in cls.model_fields:
            raise ValueError(f"unknown category {category!r}; expected one of {list(cls.model_fields)}")
        return cls(**{f: 1.0 if f == category else 0.0 for f in cls.model_fields})


def pmf_model(name: str, categories: tuple[str, ...], doc: str) -> type[PmfModel]:
    """A PMF model with one float field in [0, 1] per category, in the given order."""
    fields: dict[str, Any] = {c: (float, Field(0.0, ge=0.0, le=1.0)) for c in categories}
    model = create_model(name, __base__=PmfModel, __doc__=doc, **fields)
    return model


WeatherPmf = pmf_model("WeatherPmf", WEATHER, "PMF over weather categories.")
LightingPmf = pmf_model("LightingPmf", LIGHTING, "PMF over lighting categories.")
RoadSurfacePmf = pmf_model("RoadSurfacePmf", ROAD_SURFACE, "PMF over road-surface categories.")


# --- sections of recording.json ----------------------------------------------------------------

class SensorPose(_Strict):
    """Mount pose of a sensor: position in m, angles in rad."""

    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0
    frame: str = Field("local", description="'local' (the map frame) or 'platform' (the vehicle)")

    @field_validator("frame")
    @classmethod
    def _frame(cls, v: str) -> str:
        if v not in ("local", "platform"):
            raise ValueError("must be 'local' or 'platform'")
        return v


class Sensor(_Strict):
    id: str = Field(min_length=1)
    kind: SensorKind
    rate_hz: float | None = Field(None, gt=0)
    pose: SensorPose | None = None
    description: str | None = None


class Site(_Strict):
    name: str
    country: str | None = Field(None, pattern=r"^[A-Z]{2}$", description="ISO 3166-1 alpha-2")
    road_type: RoadType | None = None
    selection_reason: str | None = None


class Acquisition(_Strict):
    method: AcquisitionMethod
    partner: str = Field(min_length=1, description="institution that acquired the data")
    platform: str | None = Field(None, description='e.g. "ultralight aircraft, 4K camera, 20 fps"',
                                 json_schema_extra=_SHOULD)
    sensors: list[Sensor] = Field(default_factory=list, json_schema_extra=_SHOULD,
                                  description="the sensors and their mount poses")
    not_observable: list[str] = Field(
        default_factory=list,
        description="column names or prefixes this method cannot observe: a missing value there "
        "means 'not observable', not 'off' or 'absent'",
        json_schema_extra=_SHOULD,
    )
    site: Site | None = Field(None, json_schema_extra=_SHOULD,
                              description="where and why the data was acquired")

    @field_validator("sensors")
    @classmethod
    def _unique_sensor_ids(cls, v: list[Sensor]) -> list[Sensor]:
        ids = [s.id for s in v]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"sensor ids must be unique, repeated: {dup}")
        return v


class Location(_Strict):
    lon: float = Field(ge=-180, le=180)
    lat: float = Field(ge=-90, le=90)
    alt: float | None = None


class MapRef(_Strict):
    file: str = "map.xodr"
    sha256: str = Field(pattern=_SHA256)
    opendrive_version: str = Field(pattern=r"^\d+\.\d+$")


class Rights(_Strict):
    right_of_use: RightOfUse
    license: str = Field(min_length=1)
    owner: str = Field(min_length=1)


class Conditions(_Strict):
    weather: WeatherPmf | None = None  # type: ignore[valid-type]
    lighting: LightingPmf | None = None  # type: ignore[valid-type]
    road_surface: RoadSurfacePmf | None = None  # type: ignore[valid-type]
    temperature_c: float | None = None
    temperature_c_std: float | None = Field(None, ge=0)
    precipitation_mm_h: float | None = Field(None, ge=0)
    visibility_m: float | None = Field(None, ge=0)
    wind_speed_m_s: float | None = Field(None, ge=0)
    cloud_cover_okta: int | None = Field(None, ge=0, le=8)


class Thresholds(_Strict):
    ttc_s: float | None = Field(None, gt=0)
    pet_s: float | None = Field(None, gt=0)
    thw_s: float | None = Field(None, gt=0)


class TableEntry(_Strict):
    rows: int = Field(ge=0)
    sha256: str = Field(pattern=_SHA256)


class DerivedEntry(_Strict):
    table: str
    method: str
    version: str
    parameters: dict[str, Any] = Field(default_factory=dict)
    created: UtcTimestamp
    inputs: dict[str, str] = Field(
        default_factory=dict,
        description="sha256 of each input table when the derived table was made (staleness check)",
    )


class SourceInput(_Strict):
    file: str
    sha256: str | None = Field(None, pattern=_SHA256)


class Source(_Strict):
    converter: str
    converter_version: str
    inputs: list[SourceInput] = Field(default_factory=list)
    options: dict[str, Any] = Field(default_factory=dict)


class RecordingMeta(_Strict):
    """recording.json — the metadata of one recording."""

    model_config = ConfigDict(
        extra="forbid", validate_assignment=True,
        json_schema_extra={"$id": "https://aveas-format.org/schema/1.0.0/recording.json"},
    )

    format_version: str = Field(pattern=_SEMVER, description="semantic version of the format")
    recording_id: str = Field(min_length=1, description="unique id (UUID recommended)")
    title: str | None = None
    description: str | None = None
    start_time: UtcTimestamp
    duration_s: float = Field(ge=0, description="every `time` lies in [0, duration_s]")
    nominal_rate_hz: float = Field(gt=0, description="nominal sample rate; SHOULD be > 10 Hz")
    acquisition: Acquisition = Field(description="how, with what and by whom the data was acquired")
    provenance: RecordingProvenance = Field(
        description="natural, staged or simulated; mixed when the participants differ")
    location: Location = Field(description="WGS 84 centroid of the covered area")
    crs: str = Field(min_length=1, description="PROJ/EPSG string of the local frame; equal to the "
                     "map's geoReference where the map has one")
    map: MapRef = Field(description="the OpenDRIVE map every position refers to")
    coverage: str | None = Field(None, description="WKT polygon: the area observed at any time, "
                                 "local frame; everything else is unobserved",
                                 json_schema_extra=_SHOULD)
    rights: Rights = Field(description="right of use, licence and owner")
    conditions: Conditions | None = Field(None, description="static environment conditions")
    thresholds: Thresholds | None = Field(
        None, description="thresholds used to mark critical interactions")
    tables: dict[str, TableEntry] = Field(
        description="every table present, by name (states, derived/kinematics, ...): rows and "
        "SHA-256 of the file")
    derived: list[DerivedEntry] = Field(default_factory=list,
                                        description="how each derived table was made")
    source: Source | None = Field(None, description="how the recording was converted",
                                  json_schema_extra=_SHOULD)
    extras: dict[str, Any] = Field(default_factory=dict, description="free key/values")

    def to_json(self) -> str:
        """recording.json text: keys in declaration order, unset optionals left out."""
        return self.model_dump_json(indent=2, exclude_none=True)

    @property
    def start_time_ns(self) -> int:
        return timestamp_ns(self.start_time)


def recording_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of recording.json."""
    schema = RecordingMeta.model_json_schema(mode="validation")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "AVEAS recording.json"
    return schema
