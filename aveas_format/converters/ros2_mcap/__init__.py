"""ROS 2 recordings of a road vehicle in MCAP (rosbag2's default storage) -> recording.

Reads the MCAP files with ``mcap`` and decodes the CDR messages with ``rosbags``' generated
deserialisers (``mcap-ros2-support``'s generic decoder for schemas rosbags does not parse); no ROS
installation: the message definitions travel in the file. Several input files are read as one
recording.

Objects (the observed participants), from every topic of these types (or ``object_topics``):

- ``autoware_perception_msgs/msg/TrackedObjects``: pose and twist **with covariance**, the
  classification list (label + probability -> class PMF), shape dimensions (bounding box;
  cylinder: diameter x diameter; polygon: the footprint's extent), the 16-byte UUID as source id.
  The twist is in the object's own frame (Autoware's convention). ``orientation_availability``
  UNAVAILABLE: heading from the direction of motion; SIGN_UNKNOWN: flipped where it opposes the
  motion.
- ``derived_object_msgs/msg/ObjectWithCovarianceArray``: pose/twist with covariance (twist in the
  header frame), ``shape`` BOX/CYLINDER/SPHERE dimensions, ``classification`` with
  ``classification_certainty`` (0..255; 0 = not set = certain) -> PMF: the certainty on the class,
  the rest spread evenly over all 13 classes.
- ``vision_msgs/msg/Detection3DArray``: ``bbox`` centre and size, the hypotheses' ``class_id``/
  ``score`` -> PMF (``class_map`` maps ids; names such as car, person, bicycle are known), the
  best hypothesis' pose covariance, ``id`` as track id (an empty id: one participant per
  detection). No twist: velocity from positions.

Class mapping: Autoware CAR/TRUCK/BUS/TRAILER/MOTORCYCLE/BICYCLE/PEDESTRIAN/ANIMAL -> the class of
that name, UNKNOWN/HAZARD/OVER_DRIVABLE/UNDER_DRIVABLE -> other; derived_object_msgs PEDESTRIAN ->
pedestrian, BIKE -> bicycle, CAR -> car, TRUCK -> truck, MOTORCYCLE -> motorcycle, the rest ->
other. Labels that are no road user — Autoware HAZARD/OVER_DRIVABLE/UNDER_DRIVABLE,
derived_object_msgs BARRIER/SIGN, vision_msgs class ids such as ``traffic_cone`` or ``barrier``
(the table in "Labels that are not road users") — make a track whose classification is mostly
theirs be skipped with a count in a warning, unless ``keep_non_road_users`` (then class other).
A participant's ``class_pmf`` is the mean of its per-message PMFs; length/width/height the mean of
its dimensions, ``*_std`` their spread.

Ego (the recording vehicle, a participant with role ``recording_vehicle``): ``nav_msgs/msg/
Odometry`` (pose with covariance of ``child_frame_id`` in ``header.frame_id``, twist in the child
frame) and/or ``sensor_msgs/msg/NavSatFix`` (lon/lat projected through the map's CRS, the ENU
``position_covariance``; heading from the direction of motion). Its footprint centre lies
``ego_center_offset`` m ahead of ``base_frame`` (Autoware's base_link is the rear-axle centre).

Frames: every pose is transformed into ``map_frame`` through the transform tree of ``/tf`` and
``/tf_static`` (``tf2_msgs/msg/TFMessage``), the odometry (``header.frame_id`` ->
``child_frame_id``) and, without both, the NavSatFix ego track (map -> base_frame); dynamic
transforms are interpolated (linear, slerp) at each message's stamp. ``frame_offset`` = (x, y, yaw)
places ``map_frame`` in the OpenDRIVE map's local frame.

Uncertainty: the 6x6 covariances are reduced to (x, y, yaw) and (vx, vy, yaw rate) and propagated
with the full Jacobian of the frame change: ``C' = J_obj C J_obj^T + J_frame C_frame J_frame^T``,
where the frame's pose covariance is the ego odometry's (for objects in the vehicle's frames);
the twist covariance is rotated into the local frame with the heading's variance added through
the rotation's derivative. All-zero covariances mean "unknown" (null ``_std``). Velocity from a
twist in the header frame is absolute unless ``relative_velocity`` (then the ego velocity and
``omega x r`` are added).

Time: ``header.stamp`` (not the log time; a zero stamp falls back to the log time with a
warning); time zero = the earliest stamp with a transform, which also gives ``start_time``.
Decoding is per message; everything after it is vectorised per frame. Duplicate (participant, stamp) samples keep
the first. Provenance ``natural``, role ``observed`` for objects.

Large recordings: ``convert`` (of one recording) and ``validate FILE`` import in bounded memory:
the object rows are flushed every 65,536 rows into a
:class:`~aveas_format.io.resort.StatesWriter` keyed by track (spilled to a hidden temporary
directory next to the output beyond 32 MB: a row and its states cost more than an OSI sample);
what needs every row is decided first from each row's stamp and frame alone (12 bytes a row: the
rows outside the transforms' spans, time zero, the tracks' order); then the states are made a bucket of whole tracks at a time, in order (the
transforms, repeated stamps, tracks that are no road user, velocities, headings, the
participants' sizes and class PMFs are all per track;
:func:`~aveas_format.converters.common.assemble.write_by_buckets` with the participants from the
buckets), written to ``states.parquet``: the same recording as the import in memory (the same
warnings, one each with the counts over all buckets; the location's mean summed bucket by bucket:
equal to 1e-12 degrees). The Python function ``convert`` returns a recording in memory (the same
steps with one bucket); ``convert_to`` writes it in bounded memory.

Tested on: MCAP files written here with ``mcap_ros2.writer`` and the real message definitions of
``../shared/data/ros2_msgdefs/`` (Autoware TrackedObjects, derived_object_msgs, vision_msgs
Detection3DArray, Odometry, NavSatFix, /tf; tests/converters/test_ros2_mcap.py); no bag recorded
by a vehicle is in ``../shared/data``.

Modules (what lives where, from the bottom up):

- ``options``: :class:`Ros2McapOptions` and the message-type tables (supported types, preferred
  topics, class labels).
- ``decode``: opening the MCAP files and decoding their CDR messages (``channels``; ``Decoders``:
  rosbags' generated deserialisers, mcap-ros2-support's decoder as the fallback; the errors a
  corrupt file raises).
- ``tree``: the transform samples (``TransformSamples``) and the transform tree (``TransformTree``: interpolated
  lookups chained to the map frame, with the ego's pose covariance).
- ``messages``: the per-message readers (object arrays, odometry, NavSatFix, tf) -> flat rows.
- ``rows``: the object rows flushed as columns into the StatesWriter, keyed by track
  (``ObjectSink``), with each row's stamp and frame kept for the decisions over all rows.
- ``read``: which topics to read and the one pass over their messages (``read_topics``).
- ``frames``: the frame and covariance maths (``cov3``, ``to_map``, ``twist_to_map``,
  ``apply_offset``).
- ``objects``: a bucket of whole tracks in the map frame (``objects_in_map``) and as boxes
  (``object_boxes``: repeats, no road users, velocities, headings).
- ``converter``: ``convert_ros2_mcap`` (registered as ``ros2-mcap``) and ``convert_ros2_mcap_to``
  (its bounded ``writes``) and their steps: the reading and the decisions over all rows, the ego
  track, a bucket's boxes, the participants.

Importing this package registers the converter (once: the registry imports the package, the
package imports ``converter``).
"""

from aveas_format.converters.ros2_mcap.converter import convert_ros2_mcap
from aveas_format.converters.ros2_mcap.options import Ros2McapOptions

__all__ = ["Ros2McapOptions", "convert_ros2_mcap"]
