"""ASAM OpenSCENARIO XML <-> recording.

**Export** (``aveas-format export --to openscenario REC -o OUT.xosc``, :mod:`.write`): a scenario
that replays the recording as timed polylines, with the map written next to it (``OUT.xodr``, with
the recording's ``crs`` as its ``<geoReference>`` where the map has none: OpenSCENARIO has no place
for a CRS, and the re-import reads it from the map).

**Import** (``aveas-format convert --from openscenario FILE.xosc``, :mod:`.read`): OpenSCENARIO
1.0-1.3 as scenario tools write it. Parameters (``ParameterDeclarations`` at every level,
``$name``, ``${expressions}``, ``-O parameter.NAME=VALUE``) and catalog references are resolved
(:mod:`.params`); then the storyboard is replayed kinematically (:mod:`.replay`): Init teleports,
speeds and trajectories, acts and events started by their triggers, trajectories of every shape
(:mod:`.shapes`: Polyline, Clothoid, ClothoidSpline, Nurbs; World, Lane, Road, Geo and relative
positions through the OpenDRIVE engine), timed by their vertices or by the entity's speed. It is a
replay, not a simulation: what needs a controller or closed-loop dynamics (lane change actions,
synchronisation, routing, ...) is not replayed, and the warning says so. The map is ``--map`` or
the file's ``LogicFile``.

A package (not one module as before issue 18): the import grew a parameter resolver, a position and
shape evaluator and a storyboard replay, each a unit of its own; the export is unchanged.
"""

from aveas_format.converters.openscenario.read import OpenScenarioImportOptions, import_openscenario
from aveas_format.converters.openscenario.write import (
    OpenScenarioExportOptions,
    export_openscenario,
    recording_to_openscenario,
)

__all__ = ["OpenScenarioExportOptions", "OpenScenarioImportOptions", "export_openscenario",
           "import_openscenario", "recording_to_openscenario"]
