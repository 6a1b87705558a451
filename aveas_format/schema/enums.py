"""Enumerations of the format (FORMAT.md sections 3-10).

Every enum is a ``str`` enum so that its members compare equal to, and serialise as, their plain
string values in JSON and in Parquet dictionary columns.
"""

from __future__ import annotations

from enum import Enum


class StrEnum(str, Enum):
    """A string enum whose ``str()`` is its value."""

    def __str__(self) -> str:
        return self.value

    @classmethod
    def values(cls) -> tuple[str, ...]:
        return tuple(m.value for m in cls)


class AcquisitionMethod(StrEnum):
    """How the data was acquired (the paper's Table I plus simulation)."""

    ROAD_VEHICLE = "road_vehicle"
    INFRASTRUCTURE_LIDAR = "infrastructure_lidar"
    INFRASTRUCTURE_LWIR = "infrastructure_lwir"
    INFRASTRUCTURE_CAMERA = "infrastructure_camera"
    AERIAL = "aerial"
    ACCIDENT_RECONSTRUCTION = "accident_reconstruction"
    DRIVING_SIMULATOR = "driving_simulator"
    TRAFFIC_SIMULATION = "traffic_simulation"


class Provenance(StrEnum):
    """Provenance of one participant: is its behaviour natural, staged or simulated?"""

    NATURAL = "natural"
    STAGED = "staged"
    SIMULATED = "simulated"


class RecordingProvenance(StrEnum):
    """Provenance of a whole recording; ``mixed`` when its participants differ."""

    NATURAL = "natural"
    STAGED = "staged"
    SIMULATED = "simulated"
    MIXED = "mixed"


class Role(StrEnum):
    """Role of a participant in the recording."""

    OBSERVED = "observed"
    RECORDING_VEHICLE = "recording_vehicle"
    SYSTEM_UNDER_TEST = "system_under_test"
    STAGED_ACTOR = "staged_actor"
    SIMULATED_AGENT = "simulated_agent"


class RightOfUse(StrEnum):
    RESEARCH_ONLY = "research_only"
    COMMERCIAL = "commercial"


class SensorKind(StrEnum):
    LIDAR = "lidar"
    RGB_CAMERA = "rgb_camera"
    LWIR_CAMERA = "lwir_camera"
    RADAR = "radar"
    GNSS_IMU = "gnss_imu"
    SIMULATOR = "simulator"
    MANUAL = "manual"


class RoadType(StrEnum):
    MOTORWAY = "motorway"
    RURAL = "rural"
    URBAN = "urban"
    PARKING = "parking"
    MIXED = "mixed"


class UnobservedKind(StrEnum):
    OCCLUSION = "occlusion"
    SENSOR_RANGE = "sensor_range"
    FIELD_OF_VIEW = "field_of_view"
    SENSOR_OUTAGE = "sensor_outage"
    OUTSIDE_COVERAGE = "outside_coverage"


class EventKind(StrEnum):
    NEAR_MISS = "near_miss"
    CONFLICT = "conflict"
    ACCIDENT = "accident"
    LANE_CHANGE = "lane_change"
    CUT_IN = "cut_in"
    OVERTAKING = "overtaking"
    FOLLOWING = "following"
    TURNING = "turning"
    PARKING = "parking"
    HARD_BRAKING = "hard_braking"
    HANDOVER_TO_DRIVER = "handover_to_driver"
    DRIVER_INTERVENTION = "driver_intervention"


class EventOrigin(StrEnum):
    ANNOTATED = "annotated"
    DERIVED = "derived"


class Relation(StrEnum):
    """Relation of ``other_id`` to ``participant_id`` in derived/interactions."""

    LEADER = "leader"
    FOLLOWER = "follower"
    LEFT_NEIGHBOUR = "left_neighbour"
    RIGHT_NEIGHBOUR = "right_neighbour"
    CONFLICTING = "conflicting"


class TtcKind(StrEnum):
    LANE_1D = "lane_1d"
    BOX_2D = "box_2d"


class Requirement(StrEnum):
    """Requirement level of a file, table or column (FORMAT.md keywords)."""

    MUST = "MUST"
    SHOULD = "SHOULD"
    MAY = "MAY"
