"""ASAM OpenLABEL 1.0 (AVEAS profile) <-> recording, both directions.

**Export** (``aveas-format export --to openlabel REC -o OUT.json``) writes one OpenLABEL 1.0 JSON
file that follows the AVEAS profile (PyPI ``aveas-openlabel`` 0.4.17) and the map next to it
(``OUT.xodr``, named in ``metadata.opendrive``). The file validates against the official ASAM
OpenLABEL 1.0 JSON schema and loads with ``aveas_openlabel.AveasOpenLabel.from_dict``:

- ``metadata``: ``acquisition_method`` (aerial / stationary / in-vehicle), ``acquisition_partner``,
  ``acquisition_date`` (= ``start_time``), ``right_of_use``, ``opendrive``, ``projection_string``
  (= ``crs``), ``threshold_gttc``/``threshold_pret``/``threshold_thw`` (= ``thresholds``).
- ``objects`` (one per participant, key = ``participant_id``): type ``vehicle/car``,
  ``human/pedestrian``, ... (the profile's 13 classes), name = ``source_id``, ``dimensions/size``
  (+``/ustddev``), ``classification/uncertainties`` (= ``class_pmf``), ``is_recorder``,
  ``attached_to`` and the ``summary/*`` speed and acceleration extremes.
- ``frames`` (one per distinct ``time``; ``frame_properties.timestamp`` = seconds since
  ``acquisition_date``): per participant a ``bounding_box`` cuboid (x, y, z of the box centre in the
  OpenDRIVE inertial frame, yaw = ``heading``, size), ``velocity`` and ``acceleration`` in the
  vehicle frame (x forward, y left, as the profile states; yaw rate as rz), ``/ustddev`` siblings,
  ``used_road_link`` (road id: the profile's attribute name), ``open_drive/lane_id``,
  ``open_drive/lane_position`` (lane offset / lane width), ``open_drive/local_road_coordinates``
  (s, t), ``road/classification`` and ``road/number_lanes/*`` from the map, lights, interior
  signals and ``impact/gttc|thw|pret`` from the derived tables below the thresholds.
- ``contexts``: a ``scenario_context`` and ``environment_context`` (static conditions and one per
  ``environment`` row with its frame interval); ``events`` for the profile's event types (lane
  change, parking, turning, overtaking, following).

What the profile cannot carry (occlusions, full covariance, exact probabilities of lights, PET,
provenance and roles, other event kinds, the exact metadata) goes into the namespaced extension
``aveas_format`` where the OpenLABEL schema allows additional properties: ``metadata.aveas_format``
(recording.json, the ``unobserved``/``events``/``environment``/``interior`` tables, column lists,
the derived tables -- kinematics, interactions, encroachments with PET, traffic -- as column lists
with their recording.json ``derived`` entries and provenance), the ``dimensions/size`` item of each
object and the ``bounding_box`` item of each object in a frame (with the exact value of a velocity,
acceleration or z where the rebuilt one would differ in the last bit). Other readers ignore it;
our own import uses it, so export -> import is lossless and leaves derived tables fresh.

**Import** (``aveas-format convert --from openlabel FILE.json``) reads AVEAS-profile files,
including those written by ``aveas-openlabel`` itself (``to_dict(exclude_none=True)``) with its
quirks: ``used_road_link`` as the road-id name, enum values written as
``"Road__ClassificationValue.STRAIGHT"``, and the lateral automated-control flag serialised under
the longitudinal name (the second ``interior/automated_control/longitudinal`` of a frame is read
as lateral). It also reads generic ASAM OpenLABEL as dataset converters write it (VCD's KITTI
converter, the ASAM examples, TUM Traffic):

- **Cuboids** of 9 values (x, y, z, rx, ry, rz, sx, sy, sz; Euler angles ZYX) or 10 (a
  quaternion), in any coordinate system. A cuboid's axes are read through its rotation and its
  coordinate system's transform to the root: the axis nearest the root's vertical carries the
  height, the cuboid's x axis (or its y axis where x is the vertical) the length and the heading,
  the remaining one the width; the ground point lies half the box's vertical extent below its
  centre. So camera-frame cuboids (KITTI's ``CAM_LEFT``: x right, y down, z forward, sizes along
  those axes) come out with the right width, height and ground height.
- **Coordinate systems**: the chain to the root through ``pose_wrt_parent`` and each frame's
  ``frame_properties.transforms`` (either direction; a frame's transform beats the static pose),
  found by a search over both, to the reachable root of the highest rank (a ``geo_utm``/
  ``geo_wgs84`` or ``scene_cs`` system, else the root of the cuboid's own tree). A root of type
  ``geo_utm`` named like ``utm-30t`` is read as that UTM zone (or pass ``world_crs``); any other
  root is taken as the map frame. A coordinate system missing from ``coordinate_systems`` is
  taken as the root, with a warning.
- **An object with a static cuboid** in ``object_data`` whose coordinate system a frame's
  transforms move (KITTI's ``Egocar`` in ``vehicle-iso8855``, moved by the odometry) gets one box
  per such frame (within its ``frame_intervals``): the recording vehicle's trajectory.
- **Timestamps**: ``frame_properties.timestamp`` as numbers, numeric strings (integers kept
  exact: epoch nanoseconds lose nothing) or ISO 8601 texts. Their unit is inferred
  (``timestamp_unit=auto``): values that fall between 1990 and 2100 as seconds, milliseconds,
  microseconds or nanoseconds since the Unix epoch are read so (at most one unit fits), smaller
  ones count from the start in the unit their median spacing suggests (< 5: s, < 5000: ms, ...).
  ``-O timestamp_unit=s|ms|us|ns`` fixes the unit. A cuboid attribute ``timestamp`` (the ASAM
  example's per-box measurement time) beats the frame's where every box has one and they are
  absolute. Without a timestamp on every frame: frame numbers at ``rate_hz``. What was decided
  is recorded in the ``source`` block (options ``timestamp_unit`` and ``timestamps``).
- **Objects that are no participant**: an object whose type is an ignore type (KITTI's
  ``DontCare``, ``ignore``, ``noise``, a crowd) is skipped with a note, and so is one whose type
  is no road user (nuScenes' barriers and traffic cones, Waymo's signs, ...: the table in
  "Labels that are not road users" below) unless ``keep_non_road_users``. Boxes with a sentinel
  or impossible size (<= 0 as KITTI's -1000, not finite, > 400 m) are dropped with a note, and
  an object left without boxes with them: no sentinel size reaches a participant. Object types
  map to classes through the same table (``Car``, ``Cyclist``, ``vehicle.bus.rigid``,
  ``vehicle/car``, ...).
- **TUM Traffic's deviations**: a single ``cuboid`` object instead of a list, and ``type`` inside
  ``object_data`` (no top-level ``objects``).

Not supported: 2D boxes (``bbox``, ``rbbox``), polygons, polylines, point clouds and semantic
masks (image-space labels, no ground position: a file with only those is a clear error); static
cuboids without frames (no time); several files of one frame each (TUM Traffic's layout: use
``infra-lidar``, which takes many files); ``frame_intervals`` without frames; streams,
intrinsics and ontologies (read past); relations other than the profile's events.

The map comes from ``--map``, else from ``metadata.opendrive`` when that file lies next to the
input. Positions are the box centres at ground level; velocities without a ``velocity`` attribute
are computed from the positions; road coordinates are taken from the file where it has them, else
computed through the map.

How a file is read: the members of ``openlabel`` before and after the frames are read whole; the
frames in blocks of whole frames (8 MiB), each decoded by msgspec into typed Structs (frames ->
objects -> ``object_data``, attribute items typed by the profile's names, members the import does
not read skipped) and turned into columns for the whole block at once — by worker processes that
read their blocks themselves for a large plain file (``workers``), in this process for a small or
compressed one. A file the block reader does not take (no ``openlabel.frames`` object, no object
at the top level, Python's ``NaN``/``Infinity``, ``openlabel`` or ``frames`` twice) is read whole
with ``json``, its frames decoded the same way. ``aveas-format convert -v`` says which: how many
blocks, how they were cut, in how many processes. A terminal shows the reading's progress.

Large files: ``convert`` (of one file) and ``validate FILE`` import in bounded memory: the boxes
are held in a :class:`~aveas_format.io.resort.StatesWriter`, spilled to a hidden temporary
directory next to the output beyond 128 MB, and made into states a bucket of participants at a
time (in worker processes) and written to ``states.parquet``: the same recording as the import in
memory. The Python function ``convert`` returns a recording in memory; ``convert_to`` writes it in
bounded memory.

Tested on: ``../shared/data/real/vcd/openlabel100_kitti_tracking_0003.json`` (VCD's KITTI
converter), ``tests/data/third_party/vcd__openlabel100_kitti_tracking_0016_excerpt.json``
(pedestrians and a cyclist), the ASAM examples ``asam_spec__openlabel100_example_cuboids.json``
and ``..._test_bbox_simple.json``, VCD's ``vcd__openlabel100_test_{cuboids,poses,transforms}.json``
and the AVEAS profile's ``aveas__minimum_openlabel_example.json`` (``../shared/data/openlabel/``;
tests/realdata/test_openlabel.py), plus this library's own exports.

Modules (``aveas_format.converters.openlabel``): ``profile`` the profile's mapping, both
directions (``FRAME_ATTRIBUTES``: adding an attribute the import reads is one line); ``write`` +
``encode`` the export (the frames' JSON built from columns); ``read`` the importer (which path reads
a file), ``source`` the file (head, blocks of whole frames, tail), ``decode`` a block into columns,
``geometry`` cuboids in the root frame, ``boxes`` the boxes -> the decisions over all of them ->
states columns, ``participants``, ``tables``, ``findings``. Shared elsewhere:
:mod:`~aveas_format.io.timemajor` (the export's states in frame order),
:mod:`~aveas_format.io.tablejson` (the extension's tables),
:mod:`~aveas_format.converters.common.coordinate_systems`, :mod:`~aveas_format.safeio.compressed`.
"""

from __future__ import annotations

from aveas_format.converters.openlabel.read import import_openlabel, openlabel_to_recording
from aveas_format.converters.openlabel.write import export_openlabel, recording_to_openlabel
from aveas_format.io.tablejson import table_from_json, table_to_json

__all__ = ["export_openlabel", "import_openlabel", "openlabel_to_recording", "recording_to_openlabel",
           "table_from_json", "table_to_json"]
