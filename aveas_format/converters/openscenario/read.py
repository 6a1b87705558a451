"""The OpenSCENARIO import: a scenario file -> the recording of the motion it prescribes.

Parameters and catalogs are resolved first (:mod:`.params`), then the storyboard is replayed
(:mod:`.replay`) on the map (``--map`` or the ``RoadNetwork/LogicFile``, relative to the file).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from lxml import etree
from pydantic import Field

from aveas_format.converters.common.assemble import to_recording
from aveas_format.converters.common.boxes import Boxes, Rows, Sensor
from aveas_format.converters.openscenario.handedness import handedness, mirror
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.errors import FormatError, RecordingIOError, report_source
from aveas_format.mapref.build import load_map_bytes
from aveas_format.numeric import fmt_num
from aveas_format.safeio import xml_parser

CATEGORY_TO_CLASS = {"car": "car", "van": "van", "truck": "truck", "bus": "bus", "trailer": "trailer",
                     "semitrailer": "trailer", "motorbike": "motorcycle", "bicycle": "bicycle",
                     "train": "railvehicle", "tram": "railvehicle", "pedestrian": "pedestrian",
                     "animal": "animal", "wheelchair": "mobility_device"}
_KINDS = ("Vehicle", "Pedestrian", "MiscObject")


class OpenScenarioImportOptions(ImportOptions):
    provenance: str = "simulated"
    """natural / staged / simulated: what the trajectories are (default simulated)."""
    method: str = "traffic_simulation"
    """Acquisition method of the recording."""
    parameter: dict[str, str | float | int | bool] = Field(default_factory=dict)
    """Values of the scenario's global parameters (``-O parameter.NAME=VALUE``, repeatable),
    instead of their declared defaults."""
    rate_hz: float = Field(20.0, gt=0, le=1000)
    """Steps per second of the replay (samples of default motion and of untimed trajectories;
    timed polyline vertices are kept as they are)."""
    max_duration: float = Field(600.0, gt=0)
    """End of the replay (s) where no stop trigger ends it earlier."""
    handedness: Literal["auto", "right", "left"] = "auto"
    """The frame of the file's world positions: ``right`` (OpenSCENARIO's), ``left`` (CARLA's:
    y and headings mirrored), ``auto`` (left where the FileHeader description starts with
    ``CARLA:``, scenario_runner's convention, else right)."""
    variation: int | None = Field(None, ge=0)
    """Of a logical scenario (a parameter variation file): the concrete variation to import,
    0-based (the template scenario with that variation's parameter values)."""


def _read(path: Path):
    try:
        root = etree.parse(str(path), xml_parser()).getroot()
    except OSError as e:
        raise RecordingIOError(f"cannot read: {e}", path=path) from None
    except etree.XMLSyntaxError as e:
        raise FormatError(f"malformed XML: {e.msg}", path=path, line=e.lineno) from None
    if root.tag != "OpenSCENARIO":
        raise FormatError(f"not OpenSCENARIO: root element <{root.tag}>", path=path)
    return root


def _concrete(path: Path, options: OpenScenarioImportOptions):
    """The concrete scenario to replay: ``(its path, its root, the parameter values over its
    declared defaults, notes for extras)``: the file itself, or of a parameter variation file
    (:mod:`.variation`) its template with the variation ``options.variation`` (without it an
    error saying what the file is). A catalog, or a file without a storyboard, is an error
    saying so."""
    from aveas_format.converters.openscenario import variation as pv

    root = _read(path)
    values, notes = dict(options.parameter), {}
    if pv.is_logical(root):
        if options.variation is None:
            raise pv.logical_scenario_error(root, path)
        var = pv.variations(root, path)
        chosen = var[options.variation]
        template = _read(var.template)
        if pv.is_logical(template):
            raise FormatError("the template scenario of a parameter variation is itself a "
                              "parameter variation file", path=var.template)
        declared = {d.get("name") for d in
                    template.iterfind("ParameterDeclarations/ParameterDeclaration")}
        missing = sorted(set(chosen) - declared)
        if missing:
            raise FormatError(f"parameter {missing[0]!r} of the parameter variation is not "
                              f"declared by the template scenario {var.template.name}", path=path)
        if var.stochastic:
            report_source("source.openscenario.stochastic_not_expanded",
                          f"stochastic distributions are not expanded: parameter"
                          f"{'s' if len(var.stochastic) > 1 else ''} "
                          f"{', '.join(var.stochastic)} keep the template's declared values",
                          count=len(var.stochastic), file=str(path))
        values = {**chosen, **options.parameter}  # (the user's parameter.NAME wins)
        notes = {"variation": {"file": path.name, "template": var.template.name,
                               "index": options.variation, "of": len(var),
                               "parameters": chosen}}
        path, root = var.template, template
    elif options.variation is not None:
        raise FormatError("option variation: the file is a concrete scenario, not a parameter "
                          "variation file", path=path)
    if root.find("Storyboard") is None:
        cat = root.find("Catalog")
        if cat is not None:
            raise FormatError(f"a catalog (catalog {cat.get('name', '')!r}), not a scenario: "
                              "convert a scenario whose CatalogLocations lists its directory",
                              path=path)
        raise FormatError("no <Storyboard>: not a scenario (nor a parameter variation file)",
                          path=path)
    return path, root, values, notes


def _map_of(root, path: Path, map_source):
    if map_source is not None:
        return map_source
    lf = root.find("RoadNetwork/LogicFile")
    if lf is None or not lf.get("filepath"):
        raise FormatError("no map: pass --map MAP.xodr (the file has no RoadNetwork/LogicFile)",
                          path=path)
    cand = path.parent / lf.get("filepath")
    if not cand.is_file():
        raise FormatError(f"no map: pass --map MAP.xodr (LogicFile {lf.get('filepath')!r} is not "
                          f"at {cand})", path=path)
    return cand


def _inline_catalog_maneuvers(root, catalogs, path: Path) -> None:
    """``ManeuverGroup/CatalogReference`` (maneuver catalogs) replaced by the resolved
    ``Maneuver``; one that cannot be resolved is an error naming the line (its events would be
    lost otherwise)."""
    for mg in list(root.iter("ManeuverGroup")):
        for ref in mg.findall("CatalogReference"):
            try:
                entry = catalogs.resolve(ref)
            except FormatError as e:
                raise FormatError(e.message, path=path, **e.where) from None
            if entry.tag != "Maneuver":
                raise FormatError(f"catalog entry {ref.get('entryName')!r} is a <{entry.tag}>, not "
                                  "a Maneuver", path=path, line=ref.sourceline)
            mg.replace(ref, entry)


def _entity(so, catalogs) -> tuple[Any, str | None, int | None]:
    """The Vehicle / Pedestrian / MiscObject element of a ScenarioObject, or (None, why not, the
    XML line)."""
    el = next((c for c in so if c.tag in _KINDS), None)
    if el is not None:
        return el, None, None
    ref = so.find("CatalogReference")
    if ref is not None:
        try:
            el = catalogs.resolve(ref)
        except FormatError as e:
            return None, e.message, ref.sourceline
        if el.tag not in _KINDS:
            return None, (f"catalog entry {ref.get('entryName')!r} is a <{el.tag}>, not an "
                          "entity"), ref.sourceline
        return el, None, None
    kinds = [c.tag for c in so if isinstance(c.tag, str) and c.tag != "ObjectController"]
    return None, (f"<{kinds[0] if kinds else 'nothing'}> is not a Vehicle, Pedestrian or "
                  "MiscObject"), so.sourceline


@converter("openscenario", description="ASAM OpenSCENARIO XML 1.0-1.3: the storyboard's motion "
           "replayed (trajectories, speeds, teleports; parameters, catalogs)",
           patterns=("*.xosc",), method="traffic_simulation", options=OpenScenarioImportOptions,
           needs_map=False, provides=("partner", "license"),
           off_map_hint="a scenario written for CARLA is in its left-handed frame: -O "
                        "handedness=left reads it so (handedness=right: OpenSCENARIO's own)")
def import_openscenario(inputs: list[Path], *, map_source, options: OpenScenarioImportOptions):
    """The motion an OpenSCENARIO file prescribes, replayed kinematically (module
    :mod:`aveas_format.converters.openscenario.replay` says what is carried out and what is not).

    Entities: ``Vehicle``, ``Pedestrian``, ``MiscObject`` inline or by ``CatalogReference``
    (``CatalogLocations`` directories relative to the file; parameter assignments applied); the
    ``BoundingBox`` gives length, width, height and the offset of its centre from the entity's
    reference point (positions are moved to the footprint centre). Class from the category (or the
    ``aveas:class`` property of this toolkit's own export). An entity that cannot be converted is
    one located finding (:func:`~aveas_format.errors.report_source`: entity, XML line; a warning of
    ``convert``, a ``source.openscenario.*`` rule of ``validate FILE``) naming it and why; an error
    only when none can.
    """
    from aveas_format.converters.common.geometry import map_crs
    from aveas_format.converters.openscenario.replay import Replay
    from aveas_format.crs import LocalFrame
    from aveas_format.opendrive import load_map

    if len(inputs) != 1:
        raise FormatError(f"openscenario: expected one input file, got {len(inputs)}")
    given = Path(inputs[0])
    path, root, values, notes = _concrete(given, options)
    side, why = handedness(root, options.handedness)
    root, scope, catalogs = _scenario(root, path, values, side)
    map_bytes = load_map_bytes(_map_of(root, path, map_source))
    net = load_map(map_bytes)
    crs = map_crs(net.header, options)
    info, problems, where = _entities(root, catalogs, path)
    replay = Replay(root, net, {n: d["length"] for n, d in info.items()}, rate_hz=options.rate_hz,
                    max_duration=options.max_duration,
                    frame=LocalFrame(crs, net.header.offset, warn=False) if crs else None,
                    params=scope)
    replay.catalogs = catalogs
    boxes, participants, dropped = _boxes(info, replay.run(), problems, where, path)
    notes.update(_report(problems, where, replay, dropped, path))
    hdr = root.find("FileHeader")
    carried = _header_values(hdr)
    sensor = Sensor(
        method=options.method, provenance=options.provenance,
        **{"partner": (hdr.get("author") if hdr is not None else None) or "unknown",
           "title": options.title or (hdr.get("description") if hdr is not None else None),
           **carried},
        platform=f"OpenSCENARIO {path.name}", sensors=[{"id": "scenario", "kind": "simulator"}],
        extras={"openscenario": {"replay_rate_hz": options.rate_hz, "duration_s": replay.t,
                                 "catalog_files": [f.name for f in catalogs.files],
                                 "handedness": {"frame": side, "why": why},
                                 "not_converted": problems, **notes}})
    return to_recording(boxes, sensor, converter="openscenario",
                        inputs=[given] + ([path] if path != given else []), options=options,
                        map_bytes=map_bytes, participants=participants,
                        resolved={"handedness": side})


def _header_values(hdr) -> dict[str, str]:
    """What the ``FileHeader`` states of the recording.json values a person states: the licence
    (``License``: its ``spdxId``, else its ``name``) and what an export of this toolkit carries
    in its ``Properties`` (``aveas:partner``, ``aveas:start_time``...)."""
    from aveas_format.converters.common.carried import sensor_values

    if hdr is None:
        return {}
    values = {pr.get("name", "").removeprefix("aveas:"): pr.get("value")
              for pr in hdr.iterfind("Properties/Property") if pr.get("name", "").startswith("aveas:")}
    lic = hdr.find("License")
    if lic is not None and (lic.get("spdxId") or lic.get("name")):
        values["license"] = lic.get("spdxId") or lic.get("name")
    return sensor_values(values)


def _scenario(root, path: Path, values: dict[str, Any], side: str):
    """The scenario's XML with its parameters resolved (``values`` over the declared defaults),
    in the right-handed frame (``side`` left: mirrored, :mod:`.handedness`) and its maneuver
    catalog references inlined; the global parameters; the catalogs."""
    from aveas_format.converters.openscenario.params import Catalogs, declare, resolve_tree

    declared = {d.get("name") for d in root.iterfind("ParameterDeclarations/ParameterDeclaration")}
    unknown = sorted(set(values) - declared)
    if unknown:
        raise FormatError(f"parameter {unknown[0]!r} (option parameter.{unknown[0]}) is not declared "
                          f"by the scenario; declared: {', '.join(sorted(x for x in declared if x))}",
                          path=path)
    try:
        scope = declare(root.find("ParameterDeclarations"), {}, values)
        resolve_tree(root, {}, values)
        catalogs = Catalogs(root, path.parent, scope)
    except FormatError as e:
        raise FormatError(e.message, path=e.path or path, **e.where) from None
    if side == "left":
        mirror(root)
        catalogs.mirror = mirror  # (each catalog entry as it is resolved)
    _inline_catalog_maneuvers(root, catalogs, path)
    return root, scope, catalogs


def _entities(root, catalogs, path: Path):
    """Per entity that can be converted: class, bounding box (size and its centre's offset from
    the reference point), the ids and role of this toolkit's export; and the others: why not
    (``problems``) and the finding's code and XML line (``where``)."""
    from aveas_format.converters.openscenario.shapes import ShapeError, attr

    problems: dict[str, str] = {}
    where: dict[str, tuple[str, int | None]] = {}  # entity -> code, XML line of its problem
    info: dict[str, dict[str, Any]] = {}
    for so in root.iterfind("Entities/ScenarioObject"):
        name = so.get("name")
        el, why, line = _entity(so, catalogs)
        if el is None:
            problems[name] = why or "unknown entity kind"
            where[name] = ("source.openscenario.entity_not_converted", line)
            continue
        props = {pr.get("name"): pr.get("value") for pr in el.iterfind("Properties/Property")}
        cat = el.get("vehicleCategory") or el.get("pedestrianCategory") or (
            "pedestrian" if el.tag == "Pedestrian" else None)
        dims, centre = el.find("BoundingBox/Dimensions"), el.find("BoundingBox/Center")
        if dims is None:
            problems[name] = f"no BoundingBox/Dimensions in its <{el.tag}>"
            where[name] = ("source.openscenario.no_bounding_box", el.sourceline)
            continue
        if cat and cat not in CATEGORY_TO_CLASS and not props.get("aveas:class"):
            report_source("source.openscenario.unknown_category",
                          f"entity {name!r}: category {cat!r} has no class of the format: class "
                          "other", file=str(path), entity=name, line=el.sourceline)
        try:
            f = {k: attr(dims, k, math.nan) for k in ("length", "width", "height")}
            c = {k: attr(centre, k, 0.0) if centre is not None else 0.0 for k in ("x", "y")}
        except ShapeError as e:  # (a value that is no number: the entity is not converted)
            problems[name] = f"its BoundingBox: {e.message}"
            where[name] = ("source.openscenario.no_bounding_box", e.where.get("line"))
            continue
        cls = props.get("aveas:class") or CATEGORY_TO_CLASS.get(cat or "", "other")
        f.update(_assumed_size(f, cls, name, so, el, path))
        info[name] = {"class": cls, **f, "cx": c["x"], "cy": c["y"],
                      "participant_id": props.get("aveas:participant_id"),
                      "source_id": props.get("aveas:source_id") or name,
                      "role": props.get("aveas:role")}
    return info, problems, where


def _assumed_size(f: dict[str, float], cls: str, name: str, so, el, path: Path) -> dict[str, float]:
    """Where the BoundingBox states no positive length, width or height (tools that fill it with
    0 0 0): the class default (:data:`~aveas_format.converters.labels.CLASS_SIZE`) with its large
    std, and one finding naming the entity (and its catalog entry); the std of stated sizes is
    unknown (NaN)."""
    from aveas_format.converters.labels import CLASS_SIZE

    size, std = CLASS_SIZE.get(cls, CLASS_SIZE["other"])
    out = {f"{k}_std": math.nan for k in f}
    bad = [k for k in ("length", "width", "height") if not (math.isfinite(f[k]) and f[k] > 0)]
    if not bad:
        return out
    for i, k in enumerate(("length", "width", "height")):
        if k in bad:
            out[k], out[f"{k}_std"] = size[i], std[i]
    ref = so.find("CatalogReference")
    entry = (f" (catalog entry {ref.get('entryName')!r} of catalog {ref.get('catalogName')!r})"
             if ref is not None else "")
    stated = ", ".join(f"{k} {fmt_num(f[k])}" for k in bad)
    report_source("source.openscenario.zero_size",
                  f"entity {name!r}{entry}: its BoundingBox states {stated}: the default of class "
                  f"{cls} taken instead, "
                  + ", ".join(f"{k} {fmt_num(out[k])} ± {fmt_num(out[f'{k}_std'])} m" for k in bad),
                  file=str(path), entity=name, line=el.find("BoundingBox/Dimensions").sourceline)
    return out


def _boxes(info: dict[str, dict[str, Any]], ents, problems: dict[str, str],
           where: dict[str, tuple[str, int | None]], path: Path):
    """The replayed entities' boxes (their reference points moved to the footprint centre; of
    vertices repeating a time the first), their participants' columns, and the repeated times
    with another position, per entity. An entity without rows joins ``problems``; none
    converted is an error."""
    rows: dict[str, list] = {k: [] for k in ("code", "time", "x", "y", "z", "heading", "interpolated")}
    part: dict[str, list] = {k: [] for k in ("participant_id", "source_id", "class", "length",
                                             "width", "height", "length_std", "width_std",
                                             "height_std", "role")}
    dropped: list[tuple[str, float]] = []
    used_ids = {int(d["participant_id"]) for d in info.values()
                if d["participant_id"] and str(d["participant_id"]).isdigit()}
    next_id = 0
    for name, d in info.items():
        e = ents[name]
        if e.error:
            problems[name] = e.error
            where[name] = ("source.openscenario.entity_not_converted", e.error_line)
            continue
        if not e.rows:
            problems[name] = "no position (no TeleportAction or trajectory places it)"
            where[name] = ("source.openscenario.entity_not_converted", None)
            continue
        q = d["participant_id"]
        if q and str(q).isdigit():
            pid = int(q)
        else:
            while next_id in used_ids:
                next_id += 1
            pid = next_id
            used_ids.add(pid)
        first: dict[float, tuple] = {}
        for r in e.rows:
            key = round(r[0], 9)
            if key in first:
                if any(abs(a - b) > 1e-9 for a, b in zip(r[1:4], first[key][1:4])):
                    dropped.append((name, r[0]))
                continue
            first[key] = r
        for tt, x, y, z, h, filled in sorted(first.values()):
            hh = h if np.isfinite(h) else 0.0
            # the entity's reference point -> the footprint centre (the bounding box centre)
            rows["code"].append(len(part["participant_id"]))
            rows["time"].append(tt)
            rows["x"].append(x + d["cx"] * math.cos(hh) - d["cy"] * math.sin(hh))
            rows["y"].append(y + d["cx"] * math.sin(hh) + d["cy"] * math.cos(hh))
            rows["z"].append(z)
            rows["heading"].append(h)
            rows["interpolated"].append(filled)
        part["participant_id"].append(pid)
        for k in ("source_id", "class", "length", "width", "height", "length_std", "width_std",
                  "height_std"):
            part[k].append(d[k])
        part["role"].append(d["role"] if d["role"] and d["role"] not in ("None", "observed")
                            else "simulated_agent")
    if not rows["time"]:
        raise FormatError("no participants: no entity could be converted"
                          + (": " + "; ".join(f"{n!r}: {w}" + (f" (XML line {where[n][1]})"
                                                               if where[n][1] else "")
                                              for n, w in problems.items())
                             if problems else " (the file has no ScenarioObject)"), path=path)
    heading = np.asarray(rows["heading"], np.float64)
    boxes = Boxes(rows["code"], rows["time"], rows["x"], rows["y"], source_ids=part["source_id"],
                  rows=Rows([path]), z=np.asarray(rows["z"], np.float64),
                  heading=None if np.isnan(heading).any() else heading,  # (else from the motion)
                  interpolated=np.asarray(rows["interpolated"], bool) if any(rows["interpolated"])
                  else None)
    participants = {k: np.asarray(v, dtype=object if k in ("source_id", "class", "role") else
                                  np.int64 if k == "participant_id" else np.float64)
                    for k, v in part.items()
                    if not (k.endswith("_std") and np.isnan(np.asarray(v, np.float64)).all())}
    return boxes, participants, dropped


def _report(problems: dict[str, str], where: dict[str, tuple[str, int | None]], replay,
            dropped: list[tuple[str, float]], path: Path) -> dict[str, Any]:
    """The import's findings about the file (entities not converted, vertices after the end or
    repeating a time with another position, what the kinematic replay does not carry out), and
    the latter as notes for ``extras``."""
    for name, why in problems.items():
        report_source(where[name][0], f"entity {name!r} not converted: {why}", file=str(path),
                      entity=name, line=where[name][1])
    for name, n in replay.clipped.items():
        report_source("source.openscenario.after_end",
                      f"{n} trajectory vertices of entity {name!r} lie after the end of the "
                      f"scenario (its StopTrigger, at {replay.t:g} s) and were dropped", count=n,
                      file=str(path), entity=name)
    by_entity: dict[str, list[float]] = {}
    for name, tt in dropped:
        by_entity.setdefault(name, []).append(tt)
    for name, times in by_entity.items():
        report_source("source.openscenario.repeated_time",
                      f"{len(times)} trajectory vertices of entity {name!r} repeat a time (first at "
                      f"{fmt_num(times[0])} s) with another position and were dropped; the first "
                      "vertex of each time is kept", count=len(times), file=str(path),
                      entity=name, time=times[0])
    notes: dict[str, Any] = {}
    if replay.ignored_actions:
        notes["actions_not_replayed"] = dict(sorted(replay.ignored_actions.items()))
    if replay.ignored_conditions:
        notes["conditions_not_evaluated"] = sorted(replay.ignored_conditions)
    for what, counts in (("action", replay.ignored_actions),
                         ("condition", replay.ignored_conditions)):
        for kind, n in sorted(counts.items()):
            report_source("source.openscenario.not_replayed",
                          f"replayed kinematically: {what}s not "
                          f"{'replayed' if what == 'action' else 'evaluated (they never hold)'}: "
                          f"{kind} ({n})",
                          count=n, file=str(path), line=replay.ignored_lines.get(kind))
    return notes
