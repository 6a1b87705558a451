"""OpenLABEL -> recording (the import): AVEAS-profile files, this library's own (lossless through
the ``aveas_format`` extension) and generic ASAM OpenLABEL with cuboids.

:func:`import_openlabel` is the registered importer (``openlabel``), :func:`import_openlabel_to`
the import that writes its recording itself (bounded memory: ``convert`` of one file, ``validate
FILE``), :func:`openlabel_to_recording` takes a parsed document. The reading path is chosen by what
the input is (:func:`_read`):

- **blocks** (:mod:`.source`): the members before the frames read whole, the frames cut into blocks
  of whole frames and decoded (:func:`~.decode.decode_block`) in this process (small and
  compressed files) or by worker processes that read their blocks' bytes themselves (large plain
  files), the members after the frames read once the last block is;
- **whole**: a file the block reader does not take (no ``openlabel.frames`` object, no object at
  the top level, ``NaN``/``Infinity``, a repeated member: :class:`~.source.ReadWhole`) is read
  whole with ``json`` and its frames encoded into the same blocks; so is a parsed document.

Either way the blocks go through the same :class:`~.boxes.Boxes`, whose
:class:`~aveas_format.io.resort.StatesWriter` holds the boxes in memory or, for an import that
writes its recording, spills them and turns them into states a bucket of participants at a time
(:func:`~.boxes.states_of`), in worker processes. The log (``aveas-format -v``) says which path read
the file; a long read shows its progress on a terminal (``progress``).
"""

from __future__ import annotations

import logging
import os
from functools import partial
from pathlib import Path
from types import SimpleNamespace
from typing import Any, Literal

import msgspec
import pyarrow as pa
from pydantic import Field

from aveas_format.converters.common.provenance import prefetch_sha256, source_block
from aveas_format.converters.common.timestamps import TIMESTAMP_UNITS
from aveas_format.converters.openlabel.boxes import Boxes, keep_by_type, needs_size, states_of
from aveas_format.converters.openlabel.decode import decode_block
from aveas_format.converters.openlabel.findings import check_objects, claims_profile, report_frame_findings
from aveas_format.converters.common.coordinate_systems import CoordinateSystems
from aveas_format.converters.openlabel.participants import participants_of
from aveas_format.converters.openlabel.profile import EXT
from aveas_format.converters.openlabel.source import (BLOCK, ReadWhole, WrongCut, broken, cuts, load_document,
                                                      open_file, open_frames, read_tail)
from aveas_format.converters.openlabel.tables import recording_metadata, restore_derived, tables_of
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.mapref.build import load_map_bytes
from aveas_format.errors import FormatError, report_source
from aveas_format.io.resort import IMPORT_MEMORY
from aveas_format.numeric import no_gc, small_pages

log = logging.getLogger(__name__)
#: files up to this many bytes are read in this process (a few blocks: starting worker processes
#: costs more than it saves; the 27 MB sample: 1.1 s here, 1.8 s in two workers)
SMALL = 4 * BLOCK


class OpenLabelImportOptions(ImportOptions):
    world_crs: str | None = None
    """CRS (PROJ/EPSG) of the root coordinate system of generic files, e.g. EPSG:32630; default:
    read from a ``geo_utm`` root named like ``utm-30t``, else the root is the map frame."""
    method: str | None = None
    """Acquisition method (default: from ``acquisition_method``; ``road_vehicle`` where a generic
    file has an ego object, else ``infrastructure_camera``)."""
    rate_hz: float = 10.0
    """Frame rate of files without frame timestamps."""
    road_coordinates: str = "auto"
    """``file`` (take the file's road coordinates), ``map`` (compute them through the map) or
    ``auto`` (the file's where it has them, else the map's)."""
    provenance: str | None = None
    """natural / staged / simulated (default: from the file; ``staged`` where the scenario
    context says so, else natural)."""
    timestamp_unit: Literal[TIMESTAMP_UNITS] = "auto"
    """Unit of ``frame_properties.timestamp``: s, ms, us or ns; ``auto`` infers it from the values'
    magnitude (since the Unix epoch when they fall between 1990 and 2100) and spacing (since the
    start otherwise); the choice is recorded in the ``source`` block."""
    workers: int = Field(0, ge=0, exclude=True)
    """Processes reading the blocks of frames of a large file (0: one per core; 1: in this
    process; CLI ``--workers``); the recording is the same whatever the number (not recorded in
    the ``source`` block)."""
    keep_non_road_users: bool = False
    """Import objects whose type is no road user (barriers, signs, static persons...; see
    docs/converters.md "Labels that are not road users"), as class other; ignore-type objects
    (KITTI's DontCare) are never imported."""
    progress: bool = Field(False, exclude=True)
    """Show the reading's progress on a terminal (the CLI sets it; not recorded)."""


def _find_map(path: Path | None, ol: dict[str, Any], map_source) -> bytes:
    if map_source is not None:
        return load_map_bytes(map_source)
    name = (ol.get("metadata") or {}).get("opendrive")
    if name and path is not None:
        cand = path.parent / str(name)
        if cand.is_file():
            return cand.read_bytes()
        for q in path.parent.iterdir():  # case-insensitive match next to the file
            if q.name.lower() == str(name).lower():
                return q.read_bytes()
    raise FormatError("no map: pass --map MAP.xodr (metadata.opendrive "
                      + (f"{name!r} is not next to the file)" if name else "is absent)"), path=path)


def import_openlabel_to(inputs: list[Path], output: Path, *, map_source=None, options=None,
                        overwrite: bool = False, memory: int | None = None):
    """Import one OpenLABEL file and write the recording to ``output`` (atomically; the boxes
    spilled beyond ``memory`` bytes, default :data:`~aveas_format.io.resort.IMPORT_MEMORY`; the
    states written a bucket of participants at a time).
    ``(recording as written, states, states on the map)``; its states are not loaded where they
    were written in parts."""
    import shutil
    import tempfile

    from aveas_format.io.writer import check_target, write_recording

    output = Path(output)
    path = _one(inputs)
    work = Path(tempfile.mkdtemp(prefix=".openlabel-import.", dir=check_target(output, overwrite)))
    try:  # (next to the output: the states file is moved in, not copied)
        rec, written = _read(path, map_source, options or OpenLabelImportOptions(), spill_dir=work,
                             memory=memory or IMPORT_MEMORY)
        if written is None:
            rec.write(output, overwrite=overwrite)
            n = rec.states.num_rows
            return rec, n, n - rec.states.column("road_id").null_count
        states_file, summary = written
        write_recording(rec, output, overwrite=overwrite, states_file=states_file)
        return rec, states_file.rows, summary["on_road"]
    finally:
        shutil.rmtree(work, ignore_errors=True)


@converter("openlabel", description="ASAM OpenLABEL 1.0 JSON (AVEAS profile and generic cuboids)",
           patterns=("*.json", "*.json.gz", "*.json.zst"), method=None, options=OpenLabelImportOptions,
           needs_map=False, provides=("partner", "start_time", "license"), writes=import_openlabel_to,
           sniff=(b'"openlabel"',))
def import_openlabel(inputs: list[Path], *, map_source, options: OpenLabelImportOptions):
    return _read(_one(inputs), map_source, options)[0]


def _one(inputs: list[Path]) -> Path:
    if len(inputs) != 1:
        raise FormatError(f"openlabel: expected one input file, got {len(inputs)}")
    return Path(inputs[0])


def openlabel_to_recording(ol: dict[str, Any], map_bytes: bytes, *, options=None, path: Path | None = None):
    """A recording from a parsed OpenLABEL document (the object under ``openlabel``)."""
    with no_gc():
        if "openlabel" in ol and isinstance(ol["openlabel"], dict):
            ol = ol["openlabel"]
        return _document(ol, map_bytes, options or OpenLabelImportOptions(), path)[0]


def _document(ol: dict[str, Any], map_bytes: bytes, options, path: Path | None, spill_dir=None, memory=None):
    """The import of a document read whole: its frames encoded into blocks of the same decoder."""
    frames = ol.get("frames") or {}
    if not isinstance(frames, dict):
        raise FormatError("'openlabel.frames' is not an object", path=path)
    boxes = Boxes(path, spill_dir, memory)
    try:
        systems = CoordinateSystems(ol.get("coordinate_systems"))
        keys = list(frames)
        for i in range(0, len(keys), 512):
            block = {k: frames[k] for k in keys[i:i + 512]}
            boxes.add(decode_block(msgspec.json.encode(block), 0, systems))
        return _recording(ol, boxes, map_bytes, options, path)
    finally:
        boxes.close()


def _read(path: Path, map_source, options, *, spill_dir=None, memory=None):
    """``(recording, (states file, summary) or None)`` of the file at ``path`` (module docstring)."""
    with no_gc(), small_pages():
        fr = open_frames(path)
        if fr is not None:
            boxes = Boxes(path, spill_dir, memory)
            try:
                map_bytes = _find_map(path, fr.head, map_source) if "metadata" in fr.head or map_source else None
                _read_blocks(fr, boxes, options)
                ol = fr.document()
                return _recording(ol, boxes, map_bytes or _find_map(path, ol, map_source), options, path)
            except ReadWhole as e:
                log.info("%s: read whole (%s)", path, e)
            finally:
                boxes.close()
        else:
            log.info("%s: read whole (no 'openlabel.frames' object the block reader takes)", path)
        ol = load_document(path)
        return _document(ol, _find_map(path, ol, map_source), options, path, spill_dir, memory)


def _read_blocks(fr, boxes: Boxes, options) -> None:
    """The frames of ``fr`` block by block into ``boxes``: in worker processes that read their
    blocks themselves (a large plain file), else here; from a cut before a frame head that proves
    wrong (:class:`~.source.WrongCut`) on, cut by structure (here)."""
    from aveas_format.parallel import Progress, map_ordered, processes

    workers = processes(options.workers) if fr.size > SMALL else 1
    lazy = workers > 1 and not fr.compressed and hasattr(os, "pread")
    cs = fr.head.get("coordinate_systems")
    exact_from = None
    bar = Progress(fr.size, f"reading {fr.path.name}", failures=False) if options.progress else None
    by = f"{workers} worker processes" if workers > 1 else "this process"
    count = {"head": 0, "structure": 0, "lenient": 0}
    try:
        while True:
            with open_file(fr.path) as f:
                items = ((str(fr.path), cut, cs) for cut in cuts(fr, f, BLOCK, lazy, exact_from))
                jobs = map_ordered(_decode_cut, items, workers=workers)
                try:
                    for (_, (offset, data, kind), _), block in jobs:
                        if kind == "tail":
                            read_tail(fr, data, offset)
                            continue
                        if not boxes.keys:  # (the input's digest in a thread: the workers are forked by now)
                            prefetch_sha256(fr.path)
                        boxes.add(block)
                        count[kind] += 1
                        count["lenient"] += block.lenient
                        if bar is not None:
                            bar.advance(steps=(data[1] if isinstance(data, tuple) else len(data)) + 1)
                        del data, block  # (not held while the next block is read and decoded)
                    break
                except WrongCut as e:
                    log.info("%s: the cut at byte %d was inside a frame: cut by structure from there", fr.path, e.offset)
                    exact_from, lazy, workers = e.offset, False, 1
                finally:
                    jobs.close()
    finally:
        if bar is not None:
            bar.close()
    log.info("%s: %s MB read in %d blocks of whole frames (%d cut before a frame head, %d by structure; "
             "%d in the lenient layout) decoded by %s", fr.path, f"{fr.size / 1e6:,.0f}",
             count["head"] + count["structure"], count["head"], count["structure"], count["lenient"], by)
    if fr.tail and "coordinate_systems" in fr.tail and not cs and boxes.nonsimple:
        raise ReadWhole("coordinate_systems after the frames that place its cuboids")


_SYSTEMS: dict[bytes, CoordinateSystems] = {}


def _decode_cut(item: tuple) -> Any:
    """A block of :func:`~.source.cuts` decoded (in a worker process; its bytes read here where
    the cut gives their range): :class:`WrongCut` where a block cut before a frame head does not
    decode, the JSON error where one cut by structure does not (the tail: None, read by the
    caller in order; the end of a broken file: its error)."""
    path, (offset, data, kind), cs = item
    if kind == "tail":
        return None
    if kind == "broken":
        raise FormatError(data, path=path)
    if isinstance(data, tuple):
        start, n = data
        fd = os.open(path, os.O_RDONLY)
        try:
            data = os.pread(fd, n, start)
        finally:
            os.close(fd)
        if len(data) != n:
            raise FormatError("the file changed while it was read", path=path)
    key = msgspec.json.encode(cs)
    if key not in _SYSTEMS:
        _SYSTEMS.clear()
        _SYSTEMS[key] = CoordinateSystems(cs)
    buf = b"".join((b"{", data, b"}"))
    try:
        return decode_block(buf, offset, _SYSTEMS[key])
    except msgspec.DecodeError as e:
        err = broken(e, buf, offset - 1, path)
        if isinstance(err, ReadWhole) or kind == "structure":
            raise err from None
        raise WrongCut(offset) from None
    except FormatError as e:
        if e.path is None and path is not None:
            raise FormatError(e.message, path=path, **e.where) from None
        raise


def _recording(ol: dict[str, Any], boxes: Boxes, map_bytes: bytes, options, path: Path | None):
    """``(recording, (states file, summary) or None)`` from the frames read into ``boxes`` and the
    other members of the document ``ol``."""
    from aveas_format.mapref.build import build_recording, states_table
    from aveas_format.crs import LocalFrame
    from aveas_format.opendrive import load_map

    md = ol.get("metadata") or {}
    ext = md.get(EXT) if isinstance(md.get(EXT), dict) else None
    rmeta = dict((ext or {}).get("recording") or {})
    net = load_map(map_bytes)
    crs = _crs(net, rmeta, md, options, path)
    local = LocalFrame(crs, offset=net.header.offset, warn=False)
    objects = ol.get("objects") or {}
    systems = CoordinateSystems(ol.get("coordinate_systems"))
    boxes.add_static(objects, systems)
    profile = claims_profile(md, objects)
    if not profile:
        boxes.found = {k: v for k, v in boxes.found.items() if k[0] != "source.openlabel.missing_attribute"}
    report_frame_findings(boxes.found, path)
    p = boxes.decide(ol, options, keep_by_type(path, objects, options.keep_non_road_users))
    if p.n == 0 and (p.uids or p.no_state):
        raise _no_boxes_error(objects, boxes.shapes, path)
    use_file = options.road_coordinates == "file" or (options.road_coordinates == "auto" and p.has_road)
    ctx = SimpleNamespace(local=local, net=net, use_file=use_file, needs_size=needs_size(objects, p.names))
    written = None
    if boxes.writer.spilled:
        import pyarrow.parquet as pq

        log.info("%s: the boxes spilled (more than %s MB); the states written a bucket of participants "
                 "at a time", path, f"{boxes.writer.memory / 1e6:,.0f}")
        states_file, summary, infos = boxes.writer.write(
            Path(boxes.writer.spill_dir) / "states.parquet", transform=partial(_filled, p=p, ctx=ctx, fill=states_table),
            key_map=p.pid_of_idx, workers=options.workers)
        written = (states_file, summary)
        states = pq.read_schema(states_file.path).empty_table()
        meta_kw = {k: summary[k] for k in ("duration_s", "nominal_rate_hz", "location")} if summary["rows"] else {}
    else:
        got = list(boxes.writer.map(lambda t: states_of(t, p, ctx), key_map=p.pid_of_idx))
        infos = [s for _, s in got]
        tables = [t for t, _ in got]
        states = pa.concat_tables(tables, promote_options="permissive") if tables else None
        meta_kw = {}
    sizes = {p.names[i]: v.tolist() for info in infos for i, v in info.items()}
    participants, ego_seen = participants_of(p.uids, objects, p.pid_of, p.obj_ext, sizes, ext, boxes.types,
                                             boxes.subtypes)
    check_objects(p.uids, objects, boxes.types, profile, path)
    if states is None or (written is None and p.n == 0):
        states = {c: pa.array([], pa.int64() if c == "participant_id" else pa.float64())
                  for c in ("participant_id", "time", "x", "y", "heading", "vx", "vy")}
    tables, conditions, staged = tables_of(ol, ext, {p.fnum[k]: p.time_of[k] for k in p.fkeys}, p.pid_of,
                                           p.interior)
    meta_args, kw = recording_metadata(options, md, rmeta, ext, path, p.n, ego_seen, staged, conditions)
    rec = build_recording(
        map_source=map_bytes, participants=participants, states=states, **tables, crs=crs, **meta_args,
        start_time=p.start_time, recording_id=options.recording_id or rmeta.get("recording_id"),
        reference=not use_file, source=source_block("openlabel", [path] if path is not None else [], options,
                                                    resolved=p.resolved), **{**meta_kw, **kw})
    if ext is not None:
        restore_derived(rec, ext, path)
    return rec, written


def _filled(t: pa.Table, p, ctx, fill) -> tuple[pa.Table, Any]:
    """A bucket's states as the recording has them (:func:`~aveas_format.mapref.build.states_table`)."""
    states, sizes = states_of(t, p, ctx)
    return fill(states, ctx.local, None if ctx.use_file else ctx.net), sizes


def _crs(net, rmeta: dict[str, Any], md: dict[str, Any], options, path: Path | None) -> str:
    """The CRS: the map's ``<geoReference>`` (a ``crs`` option must agree with it), else the
    ``crs`` option (``--crs``), else the recording's (this library's export), else
    ``projection_string``; none: :class:`~aveas_format.errors.MissingCrsError`."""
    from aveas_format.crs import parse_crs
    from aveas_format.converters.common.geometry import missing_crs
    from aveas_format.mapref.build import check_crs

    if options.crs:
        return check_crs(options.crs, net.header.geo_reference)
    crs = net.header.geo_reference or rmeta.get("crs")
    if not crs:
        ps = md.get("projection_string")
        if ps:
            try:
                parse_crs(ps)
                crs = ps
            except FormatError:
                report_source("source.openlabel.bad_metadata", f"projection_string {ps!r} is not a usable CRS",
                              stacklevel=3, file=str(path) if path is not None else None,
                              json_path="$.openlabel.metadata.projection_string")
    if not crs:
        raise missing_crs("neither the map (<geoReference>) nor the file (metadata.projection_string) gives "
                          "a usable CRS", path=path)
    return crs


def _no_boxes_error(objects: dict[str, Any], shapes: dict[str, set[str]], path: Path | None) -> FormatError:
    from aveas_format.converters.openlabel.findings import what_objects_have

    uids = [*objects, *(u for u in shapes if u not in objects)]
    have = what_objects_have(uids, objects, shapes)
    static = sum("static cuboid" in v for v in have.values())
    flat = sum(v != "nothing" and "static cuboid" not in v for v in have.values())
    hint = (f" ({static} object(s) carry a static cuboid in object_data, which has no time: "
            "a trajectory needs frames)" if static else
            f" ({flat} objects carry labels without a cuboid only "
            f"({', '.join(sorted({k for v in have.values() if v != 'nothing' for k in v.split('+')}))}): "
            "image coordinates or shapes, no box on the ground)" if flat else "")
    return FormatError(f"no frame has a cuboid for any object{hint}", path=path)
