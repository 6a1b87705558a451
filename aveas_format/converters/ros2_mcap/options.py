"""The ROS 2 MCAP converter's options and the message-type tables: the supported message types,
the topics preferred when several carry one type, and the class labels of the object messages."""

from __future__ import annotations

from aveas_format.converters.registry import ImportOptions
from aveas_format.schema.taxonomy import CLASSES

CLS = {c: i for i, c in enumerate(CLASSES)}
NCLS = len(CLASSES)

AUTOWARE_LABELS = {0: "other", 1: "car", 2: "truck", 3: "bus", 4: "trailer", 5: "motorcycle",
                   6: "bicycle", 7: "pedestrian", 8: "animal", 9: "other", 10: "other", 11: "other"}
DERIVED_LABELS = {4: "pedestrian", 5: "bicycle", 6: "car", 7: "truck", 8: "motorcycle"}
#: labels that are no road user (docs/converters.md "Labels that are not road users"): Autoware
#: HAZARD, OVER_DRIVABLE, UNDER_DRIVABLE; derived_object_msgs BARRIER, SIGN
AUTOWARE_NOT_ROAD_USERS = {9: "hazard", 10: "over_drivable", 11: "under_drivable"}
DERIVED_NOT_ROAD_USERS = {10: "barrier", 11: "sign"}

T_TRACKED = "autoware_perception_msgs/msg/TrackedObjects"
T_DERIVED = "derived_object_msgs/msg/ObjectWithCovarianceArray"
T_DET3D = "vision_msgs/msg/Detection3DArray"
T_ODOM = "nav_msgs/msg/Odometry"
T_FIX = "sensor_msgs/msg/NavSatFix"
T_TF = "tf2_msgs/msg/TFMessage"
OBJECT_TYPES = (T_TRACKED, T_DERIVED, T_DET3D)
PREFERRED_ODOM = ("/localization/kinematic_state", "/odom", "/odometry")
PREFERRED_FIX = ("/sensing/gnss/ublox/nav_sat_fix", "/fix", "/gps/fix", "/gnss/fix")


def canonical_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` -> ``pkg/msg/Type``."""
    parts = type_name.split("/")
    return f"{parts[0]}/msg/{parts[1]}" if len(parts) == 2 else type_name


class Ros2McapOptions(ImportOptions):
    object_topics: list[str] | None = None
    """Object topics to read (default: every topic of a supported object type)."""
    odometry_topic: str | None = None
    """nav_msgs/Odometry topic of the ego (default: the only one, or /localization/kinematic_state,
    /odom); "" = none."""
    navsatfix_topic: str | None = None
    """sensor_msgs/NavSatFix topic of the ego (default: the only one); "" = none."""
    tf_topics: list[str] = ["/tf", "/tf_static"]
    """tf2_msgs/TFMessage topics (the second-named and any /tf_static are static)."""
    map_frame: str = "map"
    """The fixed frame every pose is transformed into."""
    base_frame: str = "base_link"
    """The ego vehicle's frame."""
    frame_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Pose (x, y, yaw in rad) of map_frame in the OpenDRIVE map's local frame."""
    ego_length: float = 4.9
    """Recording vehicle length (m)."""
    ego_width: float = 1.9
    """Recording vehicle width (m)."""
    ego_height: float = 1.6
    """Recording vehicle height (m)."""
    ego_class: str = "car"
    """Class of the recording vehicle."""
    ego_center_offset: float = 0.0
    """Distance (m, forward) from base_frame to the ego's footprint centre."""
    relative_velocity: bool = False
    """Twists given in the header frame are relative to the moving ego (derived_object_msgs)."""
    class_map: dict[str, str] = {}
    """vision_msgs class_id -> class (one of the 13), for ids that are not class names."""
    keep_non_road_users: bool = False
    """Import objects whose classification is no road user (Autoware HAZARD/OVER_DRIVABLE/
    UNDER_DRIVABLE, derived_object_msgs BARRIER/SIGN, vision_msgs ids such as traffic_cone) as
    class other; by default a track whose classification is mostly such is skipped, with a count
    in a warning."""
    min_existence_probability: float = 0.0
    """Drop Autoware objects below this existence probability."""
    object_sensor_kind: str = "lidar"
    """acquisition.sensors kind recorded for the object topics."""
    tf_tolerance_s: float = 0.2
    """How far (s) beyond a dynamic transform's samples a stamp may lie; objects further out are
    dropped with a warning."""

