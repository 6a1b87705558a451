"""Thresholds of the validation rules: one pydantic model with documented defaults, loadable from TOML.

``aveas-format validate --config FILE`` reads a TOML file whose tables mirror this model; every key
is optional and unknown keys are an error (a typo must not silently keep a default)::

    [kinematics]
    window_s = 0.5

    [classes.car]
    speed_max = 70.0          # m/s
    length = [2.5, 7.0]       # m

    [geo]
    lonlat_tolerance_m = 0.1

The Python API takes the same structure as a dict or a :class:`ValidationConfig`
(``aveas_format.validate(rec, config={"kinematics": {"z": 4}})``). Class tables are merged key by key
with the defaults, so ``[classes.car] speed_max = 50`` keeps the car's other limits.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from aveas_format.errors import FormatError
from aveas_format.mapref.offmap import OFF_MAP_MIN_STATES, OFF_MAP_SHARE, OFF_MAP_WALK_M


class _Section(BaseModel):
    model_config = ConfigDict(extra="forbid")


class ClassLimits(_Section):
    """Plausible ranges for one participant class (None = not checked)."""

    speed_max: float | None = Field(None, gt=0, description="m/s, over ground")
    accel_max: float | None = Field(None, gt=0, description="m/s², magnitude of the planar "
                                    "acceleration")
    jerk_max: float | None = Field(None, gt=0, description="m/s³, magnitude of the windowed "
                                   "estimate")
    yaw_rate_max: float | None = Field(None, gt=0, description="rad/s")
    length: tuple[float, float] | None = Field(None, description="m, [min, max] footprint length")
    width: tuple[float, float] | None = Field(None, description="m, [min, max] footprint width")


def _lim(speed, accel, jerk, yaw, length, width) -> ClassLimits:
    return ClassLimits(speed_max=speed, accel_max=accel, jerk_max=jerk, yaw_rate_max=yaw,
                       length=length, width=width)


#: Defaults per class: speeds at the top of what the class reaches on public roads, accelerations
#: just above what tyres deliver (~1.2 g for cars), lengths and widths of EU/US vehicle regulations
#: with a margin. They flag data errors (units, frames, tracking), not unusual driving. Jerk limits
#: apply to the windowed estimate (``[kinematics] window_s``), which smooths real jerk: braking from
#: 0 to -10 m/s² at once reads as 20 m/s³ with the default 0.5 s window.
DEFAULT_CLASSES: dict[str, ClassLimits] = {
    "car": _lim(75.0, 12.0, 25.0, 1.5, (2.5, 7.0), (1.3, 2.6)),
    "van": _lim(60.0, 11.0, 25.0, 1.5, (3.5, 8.5), (1.5, 2.7)),
    "truck": _lim(45.0, 9.0, 20.0, 1.2, (4.5, 26.0), (1.8, 3.0)),
    "bus": _lim(40.0, 9.0, 20.0, 1.2, (5.0, 26.0), (1.9, 2.8)),
    "trailer": _lim(45.0, 9.0, 20.0, 1.5, (1.0, 16.5), (0.8, 3.0)),
    "motorcycle": _lim(85.0, 12.0, 30.0, 2.5, (1.2, 3.2), (0.4, 1.4)),
    "bicycle": _lim(25.0, 7.0, 20.0, 3.0, (0.8, 3.0), (0.3, 1.3)),
    "pedestrian": _lim(12.0, 8.0, 25.0, 8.0, (0.15, 1.5), (0.15, 1.5)),
    "mobility_device": _lim(15.0, 6.0, 20.0, 4.0, (0.3, 2.5), (0.3, 1.5)),
    "pushable_pullable": _lim(10.0, 6.0, 20.0, 6.0, (0.2, 3.0), (0.2, 2.0)),
    "animal": _lim(25.0, 12.0, 40.0, 8.0, (0.1, 6.0), (0.05, 3.0)),
    "railvehicle": _lim(90.0, 4.0, 10.0, 0.8, (5.0, 400.0), (1.8, 4.0)),
    "other": _lim(90.0, 15.0, 40.0, 8.0, None, None),
}


class TimeConfig(_Section):
    tolerance_s: float = Field(1e-6, ge=0, description="slack of time against [0, duration_s]")
    resolution_s: float = Field(1e-6, gt=0, description="increments of time below this are not an "
                                "increase (time.not_increasing)")
    min_rate_hz: float = Field(10.0, gt=0, description="nominal_rate_hz below this is a warning")
    rate_tolerance: float = Field(0.1, ge=0, description="a participant's median rate may fall this "
                                  "share below nominal_rate_hz")
    gap_factor: float = Field(3.0, gt=1, description="a step longer than gap_factor / "
                              "nominal_rate_hz is a gap")
    interpolated_share: float = Field(0.5, ge=0, le=1, description="participants with more "
                                      "interpolated samples than this share are reported")


class KinematicsConfig(_Section):
    window_s: float = Field(0.5, gt=0, description="time baseline of the finite differences "
                            "(speed from positions, acceleration and jerk from velocities)")
    z: float = Field(3.0, ge=0, description="a limit is exceeded only by more than z sigma of the "
                     "estimate (propagated from the _std columns)")
    walking_speed: float = Field(2.0, ge=0, description="m/s; heading and yaw-rate checks apply "
                                 "above it")
    heading_tolerance: float = Field(0.6, gt=0, description="rad; heading vs direction of motion")
    max_reverse_speed: float = Field(6.0, ge=0, description="m/s; moving backwards (heading "
                                     "opposite to motion) is accepted below it")
    jump_tolerance_m: float = Field(1.0, ge=0, description="m; position step vs integrated velocity")
    jump_z: float = Field(5.0, ge=0, description="sigma multiplier for position jumps")
    max_lateral_speed: float = Field(3.0, gt=0, description="m/s; a step of about one lane width "
                                     "into the adjacent lane faster than this, unexplained by the "
                                     "velocity, is an instantaneous lane change")
    exact_rel_tolerance: float = Field(1e-4, ge=0, description="relative tolerance of the speed, "
                                       "acceleration, jerk and yaw-rate limits for exact values "
                                       "(std 0: simulated), e.g. 40.0003 m/s passes a 40 m/s limit")


class UncertaintyConfig(_Section):
    std_max: dict[str, float] = Field(
        default_factory=lambda: {"x_std": 10.0, "y_std": 10.0, "z_std": 10.0, "heading_std": 1.0,
                                 "vx_std": 10.0, "vy_std": 10.0, "ax_std": 10.0, "ay_std": 10.0,
                                 "yaw_rate_std": 2.0, "length_std": 5.0, "width_std": 2.0,
                                 "height_std": 2.0},
        description="largest plausible 1-sigma per _std column")
    jitter_factor: float = Field(3.0, gt=1, description="stated x/y std below the sample-to-sample "
                                 "jitter / jitter_factor is implausibly small")
    jitter_floor_m: float = Field(0.05, ge=0, description="jitter below this is never reported")


class GeoConfig(_Section):
    lonlat_tolerance_m: float = Field(0.1, ge=0, description="lon/lat vs x/y through crs")
    coverage_margin_m: float = Field(1.0, ge=0, description="states this far outside the coverage "
                                     "are still inside")


class MapConfig(_Section):
    tolerance_m: float = Field(0.1, ge=0, description="road coordinates vs x/y: max(tolerance_m, "
                               "z sigma)")
    z: float = Field(3.0, ge=0)
    s_margin_m: float = Field(0.1, ge=0, description="road_s may exceed the road length by this")
    wrong_way_angle: float = Field(2.0, gt=0, le=3.1416, description="rad; motion this far from "
                                   "the lane direction is driving against it")
    min_wrong_way_s: float = Field(0.5, ge=0, description="s; shorter wrong-way episodes are "
                                   "ignored")
    off_road_share: float = Field(OFF_MAP_SHARE, ge=0, le=1, description="a recording whose states are on "
                                  "no road of the map for more than this share is an error "
                                  "(map.mostly_off_road: wrong map, CRS, offset, axes or unit)")
    off_road_min_states: int = Field(OFF_MAP_MIN_STATES, ge=1, description="... checked from this many states on")
    off_road_walk_m: float = Field(OFF_MAP_WALK_M, ge=0, description="in a recording without vehicles, a "
                                   "state counts as off the map only this far from every lane "
                                   "(pedestrians walk beside the roads)")


class InteractionsConfig(_Section):
    overlap_depth_m: float = Field(0.2, ge=0, description="footprints are shrunk by this on every "
                                   "side before testing overlap")
    duplicate_distance_m: float = Field(1.0, gt=0, description="two tracks closer than this ...")
    duplicate_share: float = Field(0.8, gt=0, le=1, description="... for this share of their "
                                   "common samples ...")
    duplicate_min_s: float = Field(1.0, ge=0, description="... over at least this long are one "
                                   "object tracked twice")


class MetadataConfig(_Section):
    earliest_start: str = Field("1990-01-01T00:00:00Z", description="start_time before this is "
                                "implausible")
    placeholders: list[str] = Field(
        default_factory=lambda: ["", "unknown", "unspecified", "n/a", "na", "none", "tbd", "todo",
                                 "?", "-"],
        description="values of partner / licence / owner that say nothing")


class StreamingConfig(_Section):
    above_rows: int = Field(2_000_000, ge=1, description="states, interior and derived tables with "
                            "more rows than this are validated in batches, not loaded whole")
    batch_rows: int = Field(500_000, ge=1, description="rows per batch (a batch is extended to "
                            "hold each participant's states whole)")


class ValidationConfig(_Section):
    """Every threshold of the rule catalogue (see docs/validate.md)."""

    time: TimeConfig = Field(default_factory=TimeConfig)
    kinematics: KinematicsConfig = Field(default_factory=KinematicsConfig)
    classes: dict[str, ClassLimits] = Field(default_factory=lambda: dict(DEFAULT_CLASSES))
    uncertainty: UncertaintyConfig = Field(default_factory=UncertaintyConfig)
    geo: GeoConfig = Field(default_factory=GeoConfig)
    map: MapConfig = Field(default_factory=MapConfig)
    interactions: InteractionsConfig = Field(default_factory=InteractionsConfig)
    metadata: MetadataConfig = Field(default_factory=MetadataConfig)
    streaming: StreamingConfig = Field(default_factory=StreamingConfig)

    @model_validator(mode="before")
    @classmethod
    def _merge_classes(cls, data: Any) -> Any:
        """Class tables override the defaults key by key."""
        if isinstance(data, dict) and isinstance(data.get("classes"), dict):
            merged = {k: v.model_dump() for k, v in DEFAULT_CLASSES.items()}
            for name, over in data["classes"].items():
                if isinstance(over, ClassLimits):
                    over = over.model_dump(exclude_unset=True)
                if not isinstance(over, dict):
                    merged[name] = over
                    continue
                merged[name] = {**merged.get(name, {}), **over}
            data = {**data, "classes": merged}
        return data

    @field_validator("classes")
    @classmethod
    def _known_classes(cls, v: dict[str, ClassLimits]) -> dict[str, ClassLimits]:
        from aveas_format.schema.taxonomy import CLASSES

        unknown = sorted(set(v) - set(CLASSES))
        if unknown:
            raise ValueError(f"unknown classes {unknown}; known: {list(CLASSES)}")
        return v

    def limits(self, cls_name: str) -> ClassLimits:
        return self.classes.get(cls_name) or ClassLimits()

    @classmethod
    def load(cls, source: ValidationConfig | dict[str, Any] | str | Path | None) -> ValidationConfig:
        """A config from a model, a dict, a TOML file path, or None (the defaults).

        Raises FormatError naming the file and the bad key.
        """
        if source is None:
            return cls()
        if isinstance(source, ValidationConfig):
            return source
        where = None
        if isinstance(source, (str, Path)):
            where = str(source)
            try:
                source = tomllib.loads(Path(source).read_text(encoding="utf-8"))
            except tomllib.TOMLDecodeError as e:
                raise FormatError(f"invalid TOML: {e}", path=where) from None
            except OSError as e:
                raise FormatError(f"cannot read the config: {e.strerror}", path=where) from None
        from pydantic import ValidationError

        try:
            return cls.model_validate(source)
        except ValidationError as e:
            errs = "; ".join(f"{'.'.join(str(p) for p in err['loc'])}: {err['msg']}"
                             for err in e.errors()[:5])
            raise FormatError(f"invalid validation config: {errs}", path=where) from None


def config_toml(cfg: ValidationConfig | None = None) -> str:
    """The config as TOML text (the defaults when None): a starting point for ``--config``."""
    cfg = cfg or ValidationConfig()
    data = cfg.model_dump()
    lines: list[str] = []

    def val(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
        if isinstance(v, (list, tuple)):
            return "[" + ", ".join(val(x) for x in v) + "]"
        return repr(v)

    for section, body in data.items():
        if section == "classes":
            for name, lim in body.items():
                lines.append(f"[classes.{name}]")
                lines += [f"{k} = {val(v)}" for k, v in lim.items() if v is not None]
                lines.append("")
            continue
        lines.append(f"[{section}]")
        nested = {k: v for k, v in body.items() if isinstance(v, dict)}
        lines += [f"{k} = {val(v)}" for k, v in body.items() if not isinstance(v, dict)]
        lines.append("")
        for k, v in nested.items():
            lines.append(f"[{section}.{k}]")
            lines += [f"{kk} = {val(vv)}" for kk, vv in v.items()]
            lines.append("")
    return "\n".join(lines)
