"""The schema of the unified format: metadata models, table/column declarations, enums, taxonomy.

This layer imports no pyarrow, lxml or pyproj (a test checks it), so that tools can use the
declarations without the I/O stack. The core tables are declared in :mod:`.tables`; each derived
table is declared by the derivation that writes it and registered in ``TABLES`` (see
:mod:`.tables`).
"""

from aveas_format.schema.columns import Column, TableSpec
from aveas_format.schema.enums import (
    AcquisitionMethod,
    EventKind,
    EventOrigin,
    Provenance,
    RecordingProvenance,
    Relation,
    Requirement,
    RightOfUse,
    Role,
    RoadType,
    SensorKind,
    TtcKind,
    UnobservedKind,
)
from aveas_format.schema.metadata import (
    Acquisition,
    Conditions,
    DerivedEntry,
    Location,
    MapRef,
    RecordingMeta,
    Rights,
    Sensor,
    SensorPose,
    Site,
    Source,
    SourceInput,
    TableEntry,
    Thresholds,
    recording_json_schema,
)
from aveas_format.schema.tables import (
    CORE_TABLES,
    TABLES,
    derived_table,
    derived_tables,
    register_table,
    table_spec,
    tables_spec,
)
from aveas_format.schema.taxonomy import CATEGORY_SETS, CLASSES
from aveas_format.schema.versions import FORMAT_VERSION

__all__ = [
    "CATEGORY_SETS", "CLASSES", "CORE_TABLES", "FORMAT_VERSION", "TABLES",
    "Acquisition", "AcquisitionMethod", "Column", "Conditions", "DerivedEntry", "EventKind",
    "EventOrigin", "Location", "MapRef", "Provenance", "RecordingMeta", "RecordingProvenance",
    "Relation", "Requirement", "RightOfUse", "Rights", "Role", "RoadType", "Sensor", "SensorKind",
    "SensorPose", "Site", "Source", "SourceInput", "TableEntry", "TableSpec", "Thresholds", "TtcKind",
    "UnobservedKind", "derived_table", "derived_tables", "recording_json_schema", "register_table",
    "table_spec", "tables_spec",
]
