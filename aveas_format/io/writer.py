"""Writing recordings atomically, in directory form or single-file ZIP form.

Every table is conformed to its declared types, sorted by its declared order, written as Parquet
(zstd, bounded row groups, statistics, dictionary encoding only for string columns) with the
``aveas`` key-value metadata, hashed (SHA-256) and counted; recording.json is written last with those
numbers. All of it goes to a temporary sibling first and is renamed into place, so a crash never
leaves something that reads as a valid recording (FORMAT.md 1).
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import re
import shutil
import sys
import uuid
import zipfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from aveas_format._version import __version__
from aveas_format.errors import RecordingExistsError, RecordingIOError
from aveas_format.io.arrow import conform
from aveas_format.io.container import sha256_of
from aveas_format.schema.metadata import MapRef, RecordingMeta, TableEntry
from aveas_format.schema.tables import TABLES, TableSpec
from aveas_format.schema.versions import FORMAT_VERSION

AVEAS_KEY = b"aveas"
#: Rows per Parquet row group: small enough for participant-level skipping on partial reads,
#: large enough for fast scans (see docs/performance.md).
ROW_GROUP_ROWS = 131_072
COMPRESSION = "zstd"
COMPRESSION_LEVEL = 1

_XODR_VERSION = re.compile(rb"<header[^>]*?\brevMajor\s*=\s*[\"'](\d+)[\"'][^>]*?\brevMinor\s*=\s*[\"'](\d+)[\"']"
                           rb"|<header[^>]*?\brevMinor\s*=\s*[\"'](\d+)[\"'][^>]*?\brevMajor\s*=\s*[\"'](\d+)[\"']",
                           re.S)


def opendrive_version(xodr: bytes) -> str:
    """``revMajor.revMinor`` of an OpenDRIVE file's header, read without parsing the whole map."""
    m = _XODR_VERSION.search(xodr[:65536])
    if not m:
        return "1.4"  # the header attributes are required; a map without them is flagged by validate
    if m.group(1):
        return f"{int(m.group(1))}.{int(m.group(2))}"
    return f"{int(m.group(4))}.{int(m.group(3))}"


def is_sorted(table: pa.Table, keys: tuple[str, ...]) -> bool:
    """Is ``table`` sorted by ``keys`` (ascending, lexicographic)? Vectorised over the key columns."""
    keys = tuple(k for k in keys if k in table.column_names)
    if table.num_rows < 2 or not keys:
        return True
    cols = []
    for k in keys:
        arr = table.column(k)
        if not (pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type)) or arr.null_count:
            return False  # let sort_by decide for strings/dictionaries/nulls
        cols.append(arr.to_numpy())
    ok_so_far = np.zeros(table.num_rows - 1, dtype=bool)  # strictly less on an earlier key
    equal = np.ones(table.num_rows - 1, dtype=bool)
    for a in cols:
        d = a[1:] - a[:-1] if a.dtype.kind == "f" else np.sign(a[1:].astype(np.int64) - a[:-1])
        ok_so_far |= equal & (d > 0)
        equal &= d == 0
        if not (ok_so_far | equal).all():
            return False
    return bool((ok_so_far | equal).all())


def prepare_table(table: pa.Table, spec: TableSpec) -> pa.Table:
    """Conform types and sort as declared."""
    table = conform(table, spec)
    if spec.sort and not is_sorted(table, spec.sort):
        keys = [k for k in spec.sort if k in table.column_names]
        # dictionary columns sort by their string values
        view = pa.table({k: (table.column(k).cast(pa.string())
                             if pa.types.is_dictionary(table.column(k).type) else table.column(k))
                         for k in keys})
        order = pc.sort_indices(view, sort_keys=[(k, "ascending") for k in keys])
        table = take_rows(table, order)
    return table


def take_rows(table: pa.Table, order: pa.Array) -> pa.Table:
    """``table.take(order)`` with the columns taken in threads (Arrow's take runs one column at a
    time and releases the GIL: on a large table the columns go in parallel, one per core; in a
    worker process of a parallel run, one thread: the processes are the parallelism)."""
    import multiprocessing

    workers = min(table.num_columns, os.cpu_count() or 1)
    if table.num_rows < 1 << 17 or workers < 2 or multiprocessing.parent_process() is not None:
        return table.take(order)
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(workers) as pool:
        cols = list(pool.map(lambda c: pc.take(c, order), table.columns))
    return pa.Table.from_arrays(cols, schema=table.schema)


def parquet_options(schema: pa.Schema, spec: TableSpec) -> tuple[pa.Schema, dict]:
    """The schema with the ``aveas`` key and the Parquet writer options of a table of the format
    (one home for :func:`parquet_bytes` and writers that stream a table in pieces)."""
    key = {"format_version": FORMAT_VERSION, "table": spec.name,
           "creator": {"library": "aveas-format", "version": __version__}}
    md = dict(schema.metadata or {})
    md[AVEAS_KEY] = json.dumps(key).encode()
    dict_cols = [f.name for f in schema
                 if pa.types.is_dictionary(f.type) or pa.types.is_string(f.type)]
    return schema.with_metadata(md), {
        "compression": COMPRESSION, "compression_level": COMPRESSION_LEVEL,
        "use_dictionary": dict_cols or False, "write_statistics": True}


def parquet_bytes(table: pa.Table, spec: TableSpec) -> pa.Buffer:
    """Serialise one prepared table to Parquet bytes with the ``aveas`` key."""
    schema, options = parquet_options(table.schema, spec)
    sink = pa.BufferOutputStream()
    pq.write_table(table.replace_schema_metadata(schema.metadata), sink,
                   row_group_size=ROW_GROUP_ROWS, **options)
    return sink.getvalue()


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def check_target(path: Path, overwrite: bool) -> Path:
    """The directory a recording is to be written into at ``path``; RecordingExistsError where
    ``path`` exists and not ``overwrite``, RecordingIOError where the directory does not exist."""
    if path.exists() and not overwrite:
        raise RecordingExistsError("exists; pass overwrite=True (CLI: --overwrite) to replace it",
                                   path=path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise RecordingIOError("parent directory does not exist", path=parent)
    return parent


class StatesFile:
    """A ``states.parquet`` written elsewhere in parts (an importer that writes its states row
    group by row group: bounded memory), to be taken into a recording as it is: the file (on the
    same file system as the recording), its rows and SHA-256. :func:`write_recording` moves it in."""

    def __init__(self, path: Path, rows: int, sha256: str) -> None:
        self.path, self.rows, self.sha256 = Path(path), rows, sha256


def write_recording(rec, path: str | Path, *, overwrite: bool = False, form: str | None = None,
                    states_file: StatesFile | None = None) -> Path:
    """Write ``rec`` (a Recording) to ``path`` atomically; return the path.

    form: "directory" or "zip" (default: zip when the name ends in ``.zip``). states_file: the
    states as a :class:`StatesFile` (moved in, not read; ``rec.states`` is then left out and
    None afterwards).
    """
    path = Path(path)
    form = form or ("zip" if path.name.endswith(".zip") else "directory")
    if form not in ("directory", "zip"):
        raise ValueError(f"form must be 'directory' or 'zip', got {form!r}")
    parent = check_target(path, overwrite)

    members: dict[str, pa.Buffer | bytes] = {}
    entries: dict[str, TableEntry] = {}
    prepared: dict[str, pa.Table] = {}
    for name, table in rec.tables().items():
        spec = TABLES[name]
        if states_file is not None and name == "states":
            entries[name] = TableEntry(rows=states_file.rows, sha256=states_file.sha256)
            continue
        t = prepare_table(table, spec)
        buf = parquet_bytes(t, spec)
        members[spec.file] = buf
        entries[name] = TableEntry(rows=t.num_rows, sha256=sha256_of(buf))
        prepared[name] = t
    map_bytes = rec.map_source
    if map_bytes is None:
        raise RecordingIOError("the recording has no map (map.xodr is required)", path=path)
    meta: RecordingMeta = rec.meta.model_copy(deep=True)
    meta.map = MapRef(file=meta.map.file if meta.map else "map.xodr", sha256=sha256_of(map_bytes),
                      opendrive_version=opendrive_version(map_bytes))
    meta.tables = entries
    meta.format_version = FORMAT_VERSION
    members[meta.map.file] = map_bytes
    members["recording.json"] = meta.to_json().encode()

    tmp_name = f".{path.name}.tmp-{uuid.uuid4().hex[:8]}"
    tmp = parent / tmp_name
    try:
        if form == "directory":
            tmp.mkdir()
            # recording.json last: a directory without it never reads as a recording
            if states_file is not None:  # (written and synced by its writer)
                os.replace(states_file.path, tmp / TABLES["states"].file)
            for name in sorted(members, key=lambda n: n == "recording.json"):
                target = tmp / name
                target.parent.mkdir(parents=True, exist_ok=True)
                with open(target, "wb") as f:
                    f.write(memoryview(members[name]))
                    f.flush()
                    os.fsync(f.fileno())
        else:
            with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_STORED) as zf:
                for name in sorted(members, key=lambda n: n != "recording.json"):
                    zf.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)),
                                memoryview(members[name]).tobytes() if not isinstance(members[name], bytes)
                                else members[name])
                if states_file is not None:  # (streamed in, not read whole)
                    info = zipfile.ZipInfo(TABLES["states"].file, date_time=(1980, 1, 1, 0, 0, 0))
                    with open(states_file.path, "rb") as src, zf.open(info, "w", force_zip64=True) as dst:
                        shutil.copyfileobj(src, dst, 1 << 20)
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
        move_into_place(tmp, path, overwrite)
    except OSError as e:
        _remove(tmp)
        raise RecordingIOError(f"cannot write: {e.strerror or e}", path=path) from None
    except BaseException:
        _remove(tmp)
        raise
    rec.meta = meta
    rec.replace_tables(prepared)
    if states_file is not None:
        rec.states = None
    rec.path = path
    return path


def _remove(p: Path) -> None:
    if p.is_dir():
        shutil.rmtree(p, ignore_errors=True)
    elif p.exists():
        p.unlink(missing_ok=True)


def _exchange(a: Path, b: Path) -> bool:
    """Atomically swap two paths (Linux ``renameat2(RENAME_EXCHANGE)``); False if unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    at_fdcwd, rename_exchange = -100, 2
    rc = fn(at_fdcwd, os.fsencode(a), at_fdcwd, os.fsencode(b), rename_exchange)
    if rc != 0:
        err = ctypes.get_errno()
        if err in (errno.ENOSYS, errno.EINVAL, errno.ENOTSUP):
            return False
        raise OSError(err, os.strerror(err), str(b))
    return True


def move_into_place(tmp: Path, path: Path, overwrite: bool) -> None:
    """A recording (directory or ZIP) written at ``tmp`` moved to ``path`` (:func:`_replace`:
    atomically, an existing one replaced only with ``overwrite``), durably (its directory
    synced). The last step of every writer of a whole recording (``write_recording``, the
    derivations streamed into a recording)."""
    _replace(tmp, path, overwrite)
    _fsync_dir(path.parent)


def _replace(tmp: Path, path: Path, overwrite: bool) -> None:
    """Move tmp to path. An existing path is replaced atomically: files by ``os.replace``,
    directories by an atomic exchange where the OS has one (Linux), else by renaming the old one
    aside first and removing it only after the new one is in place."""
    if not path.exists():
        os.rename(tmp, path)
        return
    if not overwrite:
        raise RecordingExistsError("exists", path=path)
    if path.is_file() and tmp.is_file():
        os.replace(tmp, path)
        return
    if path.is_dir() and tmp.is_dir() and _exchange(tmp, path):
        _remove(tmp)  # now holds the old recording
        return
    old = path.parent / f".{path.name}.old-{uuid.uuid4().hex[:8]}"
    os.rename(path, old)
    try:
        os.rename(tmp, path)
    except OSError:
        os.rename(old, path)
        raise
    _remove(old)
