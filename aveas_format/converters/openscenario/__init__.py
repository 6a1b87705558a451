"""ASAM OpenSCENARIO XML <-> recording.

**Export** (``aveas-format export --to openscenario REC -o OUT.xosc``): a scenario that replays the
recording: each participant a ``ScenarioObject`` (``Vehicle`` / ``Pedestrian`` / ``MiscObject``
with its bounding box; class, source id and role in ``Properties``), an ``Init`` teleport to its
first position, and one ``FollowTrajectoryAction`` per participant with a ``Polyline`` of timed
vertices (absolute ``TimeReference``; ``WorldPosition``, or ``LanePosition`` with
``positions=lane``), thinned to ``max_rate_hz``; a ``StopTrigger`` at the end of the window. The
map is written next to it (``OUT.xodr``, the ``LogicFile``), with the recording's ``crs`` as its
``<geoReference>`` where the map has none: OpenSCENARIO has no place for a CRS, and the re-import
reads it from the map. Participants that appear later wait at their first position until their
first vertex (no spawn time before 1.3).

**Import** (``aveas-format convert --from openscenario FILE.xosc [--map MAP.xodr] [--crs CRS]``):
OpenSCENARIO 1.0-1.3 as scenario tools write it, replayed kinematically: the motion the file
prescribes, sampled at ``rate_hz``. It is a replay, not a simulation (no controllers, no
closed-loop dynamics). Precisely:

- *Parameters*: ``ParameterDeclarations`` at every level, lexically scoped; ``$name``
  references in any attribute; expressions ``${...}`` (numbers, ``$name``, ``+ - * / %``, unary
  minus, comparisons, ``and or not``, ``true``/``false``, the functions ``round floor ceil sqrt
  pow sin cos tan asin acos atan abs min max`` and ``pi``), evaluated on a whitelisted syntax tree,
  never ``eval``; ``-O parameter.NAME=VALUE`` overrides a global parameter. Not supported:
  ``ParameterSetAction``/``ParameterModifyAction`` at run time, variables.
- *Logical scenarios*: a parameter variation file (a ``ParameterValueDistribution`` over a
  template ``ScenarioFile``) is not one scenario: the import says what it is, names the template
  and the number of concrete variations; ``-O variation=N`` imports the template with the values
  of variation N of its ``Deterministic`` distributions (sets, ranges, value sets; every
  combination, the last varying fastest). ``Stochastic`` distributions are not expanded (their
  parameters keep the template's values; one finding says so).
- *Frame*: OpenSCENARIO's right-handed one, or CARLA's left-handed one where the ``FileHeader``
  description starts with ``CARLA:`` (scenario_runner's convention): then y, headings,
  ``Orientation``, the lateral ``dy`` of relative world/object positions and clothoid curvatures
  are mirrored into the map's frame (road and lane positions need nothing). ``-O
  handedness=left|right`` forces either; recording.json says which was read and why.
- *Entities*: ``Vehicle``, ``Pedestrian``, ``MiscObject``, inline or by ``CatalogReference``
  (``CatalogLocations`` directories relative to the file; the entry's parameters with the
  reference's ``ParameterAssignments``). Positions are moved from the entity's reference point to
  the bounding box centre. Class from the category. A ``BoundingBox`` of size 0 (or less: tools
  write ``0 0 0`` for an unknown size) gets the class's default size with a large std, and one
  finding names the entity and its catalog entry. An entity that cannot be converted (an
  ``ExternalObjectReference``, a catalog entry not found, an untimed trajectory at speed 0...)
  is one warning line naming it and why; an error only when none can be converted.
- *Storyboard*: ``Init`` teleports, speeds and trajectories at t = 0; acts and events start when
  their ``StartTrigger`` holds (condition groups OR-ed, conditions AND-ed, ``delay`` applied):
  ``SimulationTimeCondition``, ``StoryboardElementStateCondition``, ``ParameterCondition`` and the
  entity conditions ``ReachPosition``, ``Distance``, ``RelativeDistance``, ``TimeHeadway``,
  ``TimeToCollision``, ``Speed``, ``RelativeSpeed``, ``TraveledDistance``, ``StandStill``,
  ``EndOfRoad``, ``Offroad`` (Euclidean, between reference points; ``freespace`` subtracts half
  lengths). Other conditions
  never hold. The storyboard's ``StopTrigger`` ends the replay (else the end of the acts, or
  ``max_duration``).
- *Actions replayed*: ``TeleportAction``, ``SpeedAction`` (absolute / relative target; step, or a
  linear, cubic or sinusoidal ramp over time, rate or distance), ``FollowTrajectoryAction``
  (inline, ``TrajectoryRef`` or from a trajectory catalog), ``LaneChangeAction`` (during lane
  following: absolute or relative target lane, ``targetLaneOffset``; shape over time, distance or
  rate; the heading follows the sideways motion) and, simplified, ``SynchronizeAction``
  (the constant speed that reaches the target when the master reaches its own; ``FinalSpeed`` not
  applied). Not replayed, and named in one warning and in recording.json ``extras.openscenario``:
  lane offset actions, longitudinal distance actions, routing, controllers,
  appearance, global actions. Between trajectories an entity with a speed follows its lane at
  that speed (it stops at the end of a road without a road successor; junctions are not entered).
- *Trajectories*: shapes ``Polyline`` (``closed`` ones return to their first vertex), ``Clothoid`` (``curvatureDot``/``curvaturePrime``,
  ``startTime``/``stopTime``), ``ClothoidSpline`` (1.3) and ``Nurbs`` (rational B-spline of any
  order, weights, knots, control point times); positions ``WorldPosition``, ``LanePosition``,
  ``RoadPosition``, ``GeoPosition`` (through the recording's CRS), ``RelativeWorldPosition``,
  ``RelativeObjectPosition``, ``RelativeLanePosition``, ``RelativeRoadPosition`` (relative to the
  entity's state when the action starts) through the OpenDRIVE engine; ``RoutePosition`` and
  ``TrajectoryPosition`` are not supported (the entity is not converted, with the reason). Timing:
  vertex / control point times through the ``TimeReference`` (absolute or relative, ``scale``,
  ``offset``); untimed shapes at the entity's speed when the action starts (negative: backwards
  along the path), from ``initialDistanceOffset``; an untimed trajectory at speed 0 cannot be
  timed (the entity is not converted, and the warning says so). ``followingMode`` follow is
  replayed as position.
- *Recorded*: timed polyline vertices as they are; untimed and curved shapes, and lane following,
  one sample per step; an entity at rest at the start and end of the rest. Vertices after the
  scenario's end are dropped with a warning; a vertex repeating an entity's time too.

The map is ``--map`` or the file's ``LogicFile`` (relative to the file); where it has no
``<geoReference>``, ``--crs`` gives the recording's CRS. Provenance ``simulated``.

Tested on: esmini's ``resources/xosc/trajectory-test.xosc`` (relative lane and road positions,
Clothoid, Nurbs, TimeHeadway trigger, chained events), ``lane-change_trajectory_wp.xosc``
(untimed world polyline in Init, ``${expression}`` speed, catalog vehicle),
``pedestrian_traj_synch.xosc`` (SynchronizeAction, catalog reference by parameter) and
``EnvironmentSimulator/Unittest/xosc/traj_use_cases.xosc`` (negative speeds,
``initialDistanceOffset``, headings ``${-pi}``; no map: run on straight_500m), with esmini's
catalogs and maps (``../shared/data/real/esmini``), and esmini's
``lane-change_clothoid_based_trajectory.xosc`` (``tests/data/third_party/esmini``); plus this
toolkit's own exports.

Modules (for developers): ``write`` (export), ``read`` (import: entities, catalogs, the
recording), ``params`` (the parameter resolver: parameters, expressions, catalogs), ``variation``
(parameter variation files), ``handedness`` (CARLA's left-handed frame), ``shapes`` (the shape
evaluator: positions, trajectory shapes), ``replay`` (the storyboard replay).
"""

from aveas_format.converters.openscenario.read import OpenScenarioImportOptions, import_openscenario
from aveas_format.converters.openscenario.write import (
    OpenScenarioExportOptions,
    export_openscenario,
    recording_to_openscenario,
)

__all__ = ["OpenScenarioExportOptions", "OpenScenarioImportOptions", "export_openscenario",
           "import_openscenario", "recording_to_openscenario"]
