"""Findings of the import of a submitted file (``aveas-format validate FILE``): family ``source``.

A converter reports what is wrong with its source file but survivable (a box with a sentinel size
dropped, a PMF not summing to 1, an OSI object without a dimension, an OpenSCENARIO entity without
a bounding box) with :func:`aveas_format.errors.report_source`, located in the source's own terms
(OpenLABEL frame key and object uid, JSON path; OSI message index and object id; OpenSCENARIO
entity and XML line). ``validate FILE`` collects them while importing and hands them to the runner
(``Context.source_findings``); each code below is a rule of its own that turns them into findings.
A recording directory has none: these rules then find nothing.

One rule per code, all registered here by the one decorator (:func:`~.registry.rule`) from the
table :data:`SOURCE_RULES`; a code a converter reports without a rule here (a plugin's) is reported
by ``source.other``, so that nothing an import says is lost.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, rule


class SourceRule(NamedTuple):
    code: str
    severity: str
    title: str
    enforces: str | None
    doc: str


_DROPPED_SIZE = ("docs/format.md §4: length, width MUST be > 0 (a footprint size), so a box or object "
                 "without one cannot become a state")

#: every ``source.*`` code: (code, severity, title, enforces, doc)
SOURCE_RULES: tuple[SourceRule, ...] = (
    # -- ASAM OpenLABEL (the AVEAS profile); the importer is converters/openlabel
    SourceRule("source.openlabel.bad_size", "error", "OpenLABEL box with an impossible size",
               _DROPPED_SIZE,
               "An OpenLABEL object's cuboid or bbox has a non-positive or sentinel size (e.g. "
               "-1000, 0). The box is dropped from the frame's rows (its state is lost); the "
               "finding names the frame key and object uid of the first such box and counts all."),
    SourceRule("source.openlabel.duplicate_state", "error", "OpenLABEL boxes repeat a state",
               "docs/format.md §5: (participant_id, time) MUST be unique",
               "Two boxes of the same object at the same frame time. The first is kept, the others "
               "are dropped; the finding names the frame and uid of the first repeat."),
    SourceRule("source.openlabel.unknown_type", "warning", "OpenLABEL object type not in the profile",
               "docs/format.md §4: class is one of the 13 classes (the AVEAS OpenLABEL object types); an "
               "object SHOULD carry one of them",
               "An object's ``type`` is none of the AVEAS OpenLABEL profile's 13 classes; the "
               "participant gets class ``other``."),
    SourceRule("source.openlabel.pmf_sum", "warning", "OpenLABEL class PMF does not sum to 1",
               "docs/format.md §4: class_pmf is a PMF; it SHOULD sum to 1",
               "An object's class probabilities do not sum to 1 (within tolerance); they are "
               "normalised on import, so the stored PMF differs from the submitted one."),
    SourceRule("source.openlabel.missing_attribute", "error",
               "OpenLABEL object misses a mandatory attribute",
               "AVEAS OpenLABEL profile: the mandatory object attributes MUST be present",
               "An object or its frame data lacks an attribute the AVEAS OpenLABEL profile makes "
               "mandatory; the finding names the frame, the uid and the JSON path."),
    SourceRule("source.openlabel.unknown_coordinate_system", "warning",
               "OpenLABEL coordinate system not declared",
               "AVEAS OpenLABEL profile: a box's coordinate_system SHOULD be one the file declares",
               "A box refers to a coordinate system the file's ``coordinate_systems`` does not "
               "declare (or one without a usable projection); it is read in the root frame."),
    SourceRule("source.openlabel.bad_metadata", "warning", "OpenLABEL metadata unusable",
               "docs/format.md §3: recording.json's start_time and crs come from the OpenLABEL "
               "metadata, which SHOULD be valid (ISO 8601 acquisition_date, a usable "
               "projection_string)",
               "A value of the OpenLABEL ``metadata`` (acquisition date, projection string...) "
               "cannot be read; the import uses the option or the default instead."),
    SourceRule("source.openlabel.extension_skipped", "warning",
               "OpenLABEL AVEAS extension entry skipped",
               "the AVEAS extension of an OpenLABEL file SHOULD hold only tables and entries this "
               "toolkit knows (a skipped entry's data is not imported)",
               "An entry of the file's AVEAS extension (a derived table, a table of an unknown "
               "name, a malformed entry) is skipped; the finding names its JSON path."),
    # -- ASAM OSI; the importer is converters/osi.py
    SourceRule("source.osi.missing_base", "error", "OSI moving object without id or base",
               "docs/format.md §5: x, y MUST be given for every state (OSI: a MovingObject's id and "
               "base.position)",
               "A GroundTruth ``moving_object`` has no ``id`` or no ``base``: it cannot be placed, "
               "and the sample is skipped. Located by the OSI message index (and object id where "
               "there is one)."),
    SourceRule("source.osi.missing_dimension", "error", "OSI moving object without a dimension",
               _DROPPED_SIZE,
               "A moving object has no positive ``base.dimension`` length and width in a message. "
               "Where a later message of the same object gives one, that size is used; where none "
               "does, the object is not imported. Located by message index and object id."),
    SourceRule("source.osi.time_not_increasing", "warning", "OSI timestamps do not increase",
               "ASAM OSI: a trace's messages SHOULD follow each other in time (docs/format.md §5: time "
               "increases along a trajectory)",
               "A GroundTruth's ``timestamp`` is earlier than the previous message's. The states "
               "are sorted by time on import; the finding names the first such message."),
    SourceRule("source.osi.unknown_type", "warning", "OSI object type unknown",
               "docs/format.md §4: class is one of the 13 classes; an object SHOULD say what it is",
               "A moving object's ``type`` (or its vehicle classification type) is UNKNOWN or not "
               "mapped; the participant gets class ``other``."),
    # -- ASAM OpenSCENARIO; the importer is converters/openscenario
    SourceRule("source.openscenario.no_bounding_box", "error",
               "OpenSCENARIO entity without a bounding box", _DROPPED_SIZE,
               "A Vehicle, Pedestrian or MiscObject has no ``BoundingBox/Dimensions``; the entity "
               "is not converted. Located by the entity name and its XML line."),
    SourceRule("source.openscenario.entity_not_converted", "error",
               "OpenSCENARIO entity not converted",
               "docs/format.md §4: every participant MUST have states (an entity that cannot be placed "
               "or replayed has none)",
               "An entity cannot be converted: its catalog entry cannot be resolved, it is not a "
               "Vehicle/Pedestrian/MiscObject, no action places it, or an action of it cannot be "
               "replayed. The finding names the entity, the XML line and why."),
    SourceRule("source.openscenario.zero_size", "warning",
               "OpenSCENARIO bounding box of size 0",
               "docs/format.md §4: length, width MUST be > 0; an assumed size SHOULD say how "
               "uncertain it is (its _std)",
               "An entity's ``BoundingBox/Dimensions`` states a length, width or height of 0 (or "
               "less), as tools write for an unknown size: the participant gets its class's "
               "default size with a large std (the spread of the class). The finding names the "
               "entity, its catalog entry and the XML line."),
    SourceRule("source.openscenario.stochastic_not_expanded", "info",
               "OpenSCENARIO stochastic distribution not expanded", None,
               "A concrete variation of a parameter variation file was imported (option "
               "``variation``): its ``Stochastic`` distributions name no concrete values and are "
               "not drawn from; their parameters keep the template's declared values."),
    SourceRule("source.openscenario.unknown_category", "warning",
               "OpenSCENARIO category without a class",
               "docs/format.md §4: class is one of the 13 classes; an entity's category SHOULD map to "
               "one",
               "An entity's ``vehicleCategory``/``pedestrianCategory`` (or a MiscObject) has no "
               "class of the format; the participant gets class ``other``."),
    SourceRule("source.openscenario.vertex_without_time", "warning",
               "OpenSCENARIO trajectory vertex without time",
               "ASAM OpenSCENARIO: with a TimeReference, every vertex of a trajectory SHOULD have "
               "a time",
               "A trajectory followed with a ``TimeReference/Timing`` has a vertex without "
               "``time``: the whole trajectory is followed at the entity's speed instead of its "
               "times. Located by entity and the vertex's XML line."),
    SourceRule("source.openscenario.repeated_time", "warning",
               "OpenSCENARIO trajectory repeats a time",
               "docs/format.md §5: (participant_id, time) MUST be unique; vertices of one time SHOULD "
               "agree",
               "Trajectory vertices of an entity at the same time with different positions; the "
               "first of each time is kept."),
    SourceRule("source.openscenario.after_end", "info",
               "OpenSCENARIO vertices after the end", None,
               "Timed trajectory vertices of an entity lie after the scenario's end (its "
               "StopTrigger or ``max_duration``) and are not replayed."),
    SourceRule("source.openscenario.not_replayed", "info",
               "OpenSCENARIO actions or conditions not replayed", None,
               "Actions (routing, controllers, ...) the kinematic replay does not carry out, or "
               "conditions it does not evaluate (they never hold); the count is the number of "
               "such elements."),
    # -- anything else a converter says about its source
    SourceRule("source.other", "warning", "Other finding of the import",
               "a submitted file SHOULD import without findings",
               "What an import reports about its source without a rule of its own: a code of a "
               "plugin converter, or a warning of a converter that does not locate its findings "
               "yet (the message is the converter's)."),
)

_CODES = {r.code for r in SOURCE_RULES}


def _register(spec: SourceRule) -> None:
    def check(ctx: Context) -> Iterator[Hit]:
        for f in ctx.source_findings:
            if f.code == spec.code or (spec.code == "source.other" and f.code not in _CODES):
                extra = {} if f.code == spec.code else {"source_code": f.code}
                yield Hit(**f.location, source_message=f.message, count=f.count, **extra)

    check.__doc__ = spec.doc
    check.__name__ = spec.code.replace(".", "_")
    rule(spec.code, spec.severity, spec.title, "{source_message}", enforces=spec.enforces)(check)


for _spec in SOURCE_RULES:
    _register(_spec)
