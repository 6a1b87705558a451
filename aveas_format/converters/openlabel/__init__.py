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
as lateral). It also reads generic ASAM OpenLABEL with cuboids (9 values with Euler angles or 10
with a quaternion) in any coordinate system, chained through ``coordinate_systems``
``pose_wrt_parent`` and per-frame ``frame_properties.transforms`` to the root frame; a root of
type ``geo_utm`` named like ``utm-30t`` is read as that UTM zone (or pass ``world_crs``), any other
root is taken as the map frame. Per-frame timestamps in Unix seconds set ``start_time``.

The map comes from ``--map``, else from ``metadata.opendrive`` when that file lies next to the
input. Positions are the box centres at ground level; velocities without a ``velocity`` attribute
are computed from the positions; road coordinates are taken from the file where it has them, else
computed through the map.

Modules (``aveas_format.converters.openlabel``): ``profile`` the profile's mapping shared by both
directions (classes, events, lights, conditions, timestamps, the extension's table encoding);
``write`` recording -> OpenLABEL (``recording_to_openlabel``, the exporter); ``read`` OpenLABEL ->
recording (``openlabel_to_recording``, the importer); ``frames`` the frames into per-box columns and
the coordinate systems of generic files; ``stream`` the streamed, bounded reading of large files.
"""

from __future__ import annotations

from aveas_format.converters.openlabel.profile import table_from_json, table_to_json
from aveas_format.converters.openlabel.read import import_openlabel, openlabel_to_recording
from aveas_format.converters.openlabel.write import export_openlabel, recording_to_openlabel

__all__ = ["export_openlabel", "import_openlabel", "openlabel_to_recording", "recording_to_openlabel",
           "table_from_json", "table_to_json"]
