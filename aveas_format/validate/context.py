"""What rules look at: a recording loaded leniently, with every loading problem kept as data.

``aveas_format.open`` raises on the first problem; validation instead wants to report all of them.
:class:`Context` reads recording.json and each table on first use and records what went wrong
(``problems``) for the structure rules to report, so later rules simply see ``None`` for what could
not be read.

Large tables (states, interior, derived tables above ``[streaming] above_rows`` rows) are not
loaded whole: they are *streamed*. :meth:`Context.passes` yields the context itself (whose
``row_tables`` are the tables loaded whole) and then one batch context per batch of a streamed
table, whose ``table(name)`` is that batch and whose ``file_rows`` map batch rows to file rows.
States batches hold each participant's samples whole (row groups are cut at a participant
boundary), so per-participant rules see complete trajectories.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
from pydantic import ValidationError

from aveas_format.errors import FormatError
from aveas_format.io.container import Container, sha256_of
from aveas_format.io.recording import Recording
from aveas_format.safeio import load_json
from aveas_format.schema.metadata import RecordingMeta
from aveas_format.schema.tables import TABLES
from aveas_format.schema.versions import VersionError, migrate_meta


#: tables that may be streamed (participants, events, unobserved, environment are read whole:
#: every rule needs them at once, and they are small)
_STREAMABLE_PREFIX = "derived/"
_STREAMABLE = ("states", "interior")
#: cache entries that do not depend on the states rows and are shared with batch contexts
_SHARED_CACHE = ("map.checks", "unobserved.geoms", "geo.coverage")


def checked(table: pa.Table) -> pa.Table:
    """``table`` after Arrow's full validation of every column (a damaged file can decode into text
    that is no UTF-8, offsets past the data...: what the rules would trip over); an ArrowInvalid
    naming the column where it fails (the caller reports the table as unreadable)."""
    for name, col in zip(table.column_names, table.columns):
        try:
            col.validate(full=True)
        except pa.ArrowInvalid as e:
            raise pa.ArrowInvalid(f"column {name!r}: {str(e).splitlines()[0]}") from None
    return table


@dataclass
class Streamed:
    """A table validated in batches: its Parquet file and whether batches keep participants whole."""

    name: str
    pf: pq.ParquetFile
    rows: int
    by_participant: bool

    def batches(self, batch_rows: int):
        """(table, file rows) of each batch, in file order."""
        md = self.pf.metadata
        offsets = np.r_[0, np.cumsum([md.row_group(g).num_rows for g in range(md.num_row_groups)])]
        pid_idx = self.pf.schema_arrow.get_field_index("participant_id")
        pending: list[pa.Table] = []
        pending_rows: list[np.ndarray] = []
        n = 0
        last = md.num_row_groups - 1
        for g in range(md.num_row_groups):
            t = checked(self.pf.read_row_group(g))
            pending.append(t)
            pending_rows.append(np.arange(offsets[g], offsets[g] + t.num_rows, dtype=np.int64))
            n += t.num_rows
            if n < batch_rows or g == last:
                continue
            tab = pa.concat_tables(pending)
            rows = np.concatenate(pending_rows)
            if not self.by_participant:
                yield tab, rows
                pending, pending_rows, n = [], [], 0
                continue
            # the participant at the end of this row group may go on in the next one: keep it
            cut = md.row_group(g).column(pid_idx).statistics.max
            keep = np.asarray(pc.fill_null(pc.less(tab.column("participant_id"), cut), True)
                              .to_numpy(zero_copy_only=False), bool)
            if keep.any():
                yield tab.filter(keep), rows[keep]
            rest = ~keep
            pending, pending_rows = [tab.filter(rest)], [rows[rest]]
            n = int(rest.sum())
        if pending:
            yield pa.concat_tables(pending), np.concatenate(pending_rows)


def _participant_sorted(pf: pq.ParquetFile) -> bool:
    """True when the row groups' participant_id statistics do not overlap (max of one <= min of the
    next), so that only the participant at a row-group end can go on in the next row group."""
    idx = pf.schema_arrow.get_field_index("participant_id")
    if idx < 0 or not pa.types.is_integer(pf.schema_arrow.field(idx).type):
        return False
    prev = None
    md = pf.metadata
    for g in range(md.num_row_groups):
        st = md.row_group(g).column(idx).statistics
        if st is None or not st.has_min_max:
            return False
        if prev is not None and st.min < prev:
            return False
        prev = st.max
    return True


@dataclass
class Problem:
    """A loading problem: ``kind`` selects the structure rule that reports it."""

    kind: str
    fields: dict[str, Any] = field(default_factory=dict)


class Context:
    """Lazily loaded pieces of one recording (from a path or an in-memory Recording)."""

    def __init__(self, source: str | Path | Recording, config: Any = None) -> None:
        from aveas_format.validate.config import ValidationConfig

        #: the thresholds (:class:`~aveas_format.validate.config.ValidationConfig`)
        self.config = ValidationConfig.load(config)
        #: results shared between rules (e.g. the pairs of nearby participants), by key
        self.cache: dict[str, Any] = {}
        self.problems: list[Problem] = []
        #: findings an import reported about the submitted source file (``validate FILE``): a list
        #: of :class:`aveas_format.errors.SourceFinding`, read by the ``source.*`` rules
        self.source_findings: list[Any] = []
        #: merged results of the collectors (set by the runner before the recording rules run)
        self.collected: dict[str, Any] = {}
        #: tables validated in batches (empty for small recordings and in-memory ones)
        self.streamed: dict[str, Streamed] = {}
        #: in a batch context: the batch's number and, per table, the file row of each batch row
        self.batch_index = 0
        self.file_rows: dict[str, np.ndarray] = {}
        self._row_tables: list[str] | None = None
        self._keys: dict[str, pa.Table | None] = {}
        self.recording: Recording | None = source if isinstance(source, Recording) else None
        self.container: Container | None = None
        if self.recording is None:
            self.container = Container(source)  # raises RecordingIOError: nothing to validate
            self.name = str(source)
        else:
            self.name = str(self.recording.path or self.recording.meta.recording_id)

    def problem(self, kind: str, **fields: Any) -> None:
        self.problems.append(Problem(kind, fields))

    def problems_of(self, kind: str) -> list[Problem]:
        self._load_all()
        return [p for p in self.problems if p.kind == kind]

    def close(self) -> None:
        if self.container is not None:
            self.container.close()

    # -- recording.json ---------------------------------------------------------------------
    @cached_property
    def meta_dict(self) -> dict[str, Any] | None:
        """recording.json as parsed JSON (None if missing or broken)."""
        if self.recording is not None:
            return json.loads(self.recording.meta.to_json())
        assert self.container is not None
        if not self.container.exists("recording.json"):
            self.problem("missing_file", file="recording.json")
            return None
        raw = self.container.read_bytes("recording.json")
        try:
            data = load_json(raw)
        except FormatError as e:
            self.problem("broken_json", file="recording.json", line=e.where.get("line"),
                         error=e.message)
            return None
        if not isinstance(data, dict):
            self.problem("broken_json", file="recording.json", line=1, error="not a JSON object")
            return None
        return data

    def meta_part(self, key: str) -> dict[str, Any]:
        """A section of recording.json as a dict ({} where absent or not an object)."""
        d = self.meta_dict
        v = d.get(key) if isinstance(d, dict) else None
        return v if isinstance(v, dict) else {}

    @cached_property
    def meta(self) -> RecordingMeta | None:
        """The validated metadata model (migrated), None if invalid."""
        if self.recording is not None:
            return self.recording.meta
        data = self.meta_dict
        if data is None:
            return None
        try:
            data, _ = migrate_meta(dict(data))
        except VersionError as e:
            self.problem("format_version", file="recording.json", error=str(e),
                         value=data.get("format_version"))
            return None
        try:
            return RecordingMeta.model_validate(data)
        except ValidationError as e:
            for err in e.errors():
                self.problem("metadata", file="recording.json",
                             column=".".join(str(p) for p in err["loc"]) or "(top level)",
                             error=err["msg"])
            return None

    # -- tables -----------------------------------------------------------------------------
    @cached_property
    def table_names(self) -> list[str]:
        if self.recording is not None:
            return list(self.recording.tables())
        assert self.container is not None
        files = set(self.container.names())
        tables = self.meta_part("tables")
        listed = {k for k in tables if isinstance(k, str)}
        return [n for n in TABLES if TABLES[n].file in files or n in listed]

    @cached_property
    def _tables(self) -> dict[str, pa.Table | None]:
        out: dict[str, pa.Table | None] = {}
        for name in self.table_names:
            out[name] = self._read(name)
        return out

    def table(self, name: str) -> pa.Table | None:
        """The table as stored (not cast), or None if absent, unreadable, or streamed (in a batch
        context: the batch of the streamed table)."""
        return self._tables.get(name)

    @property
    def row_tables(self) -> list[str]:
        """The tables whose rows this context checks (``scope="rows"`` rules iterate these): the
        tables loaded whole, or in a batch context the batch's table."""
        if self._row_tables is not None:
            return self._row_tables
        _ = self._tables
        return [n for n in self.table_names if n not in self.streamed]

    def row_table(self, name: str) -> pa.Table | None:
        """``table(name)`` if its rows are checked in this context, else None."""
        return self.table(name) if name in self.row_tables else None

    def schema(self, name: str) -> pa.Schema | None:
        """The Arrow schema of a table as stored (also of a streamed one), None if unreadable."""
        _ = self._tables
        if name in self.streamed:
            return self.streamed[name].pf.schema_arrow
        t = self.table(name)
        return t.schema if t is not None else None

    def num_rows(self, name: str) -> int | None:
        """Rows of a table (also of a streamed one), None if unreadable."""
        _ = self._tables
        if name in self.streamed:
            return self.streamed[name].rows
        t = self.table(name)
        return t.num_rows if t is not None else None

    def key_table(self, name: str, columns: tuple[str, ...] | None = None) -> pa.Table | None:
        """Only the key columns (default: the table's declared key, those present) of a table, all
        rows in file order; read from the file alone for a streamed table (and cached)."""
        spec = TABLES[name]
        cols = tuple(columns or spec.key)
        _ = self._tables
        if name not in self.streamed:
            t = self.table(name)
            return t.select([c for c in cols if c in t.column_names]) if t is not None else None
        ck = f"{name}:{','.join(cols)}"
        for other, t in self._keys.items():  # a cached superset serves (states: pid, time)
            if t is not None and other.split(":", 1)[0] == name and all(
                    c in t.column_names or c not in self.streamed[name].pf.schema_arrow.names
                    for c in cols):
                return t.select([c for c in cols if c in t.column_names])
        if set(cols) <= set(spec.key):  # read the whole key once; subsets are served from it
            cols = spec.key
            ck = f"{name}:{','.join(cols)}"
        if ck not in self._keys:
            st = self.streamed[name]
            present = [c for c in cols if c in st.pf.schema_arrow.names]
            try:
                self._keys[ck] = st.pf.read(columns=present)
            except (pa.ArrowException, OSError) as e:
                self._unreadable(name, e)
                self._keys[ck] = None
        t = self._keys[ck]
        return t.select([c for c in columns or spec.key if c in t.column_names]) if t is not None \
            else None

    def passes(self):
        """This context, then one batch context per batch of each streamed table."""
        _ = self._tables
        yield self
        if not self.streamed:
            return
        # what batches share is loaded once, here
        for prop in ("meta", "map_bytes", "network", "frame", "participants_view"):
            getattr(self, prop)
        batch_rows = self.config.streaming.batch_rows
        for name, st in self.streamed.items():
            k = 0
            try:
                for table, rows in st.batches(batch_rows):
                    yield self._batch(name, table, rows, k)
                    k += 1
            except (pa.ArrowException, OSError) as e:
                self._unreadable(name, e, f"batch {k}: ")

    def _batch(self, name: str, table: pa.Table, rows: np.ndarray, k: int) -> Context:
        b = Context.__new__(Context)
        d = b.__dict__
        for key in ("config", "recording", "container", "name", "problems", "meta_dict", "meta",
                    "table_names", "map_bytes", "network", "frame", "participants_view",
                    "_file_info", "streamed"):
            if key in self.__dict__:
                d[key] = self.__dict__[key]
        d["cache"] = {k_: v for k_, v in self.cache.items() if k_ in _SHARED_CACHE}
        d["collected"] = {}
        d["_tables"] = {**self._tables, name: table}
        d["_row_tables"] = [name]
        d["batch_index"] = k
        d["file_rows"] = {name: rows}
        d["_keys"] = {}
        return b

    def file_info(self, name: str) -> dict[str, Any]:
        """sha256, bytes, rows, row_groups and the raw ``aveas`` key of a table's file."""
        _ = self._tables
        return self._file_info.get(name, {})

    @cached_property
    def _file_info(self) -> dict[str, dict[str, Any]]:
        return {}

    def _read(self, name: str) -> pa.Table | None:
        if self.recording is not None:
            t = self.recording.table(name)
            try:
                return checked(t) if t is not None else None
            except pa.ArrowInvalid as e:
                self._unreadable(name, e)
                return None
        assert self.container is not None
        spec = TABLES[name]
        if not self.container.exists(spec.file):
            self.problem("missing_file", file=spec.file, table=name)
            return None
        if self._stream(name):
            return None
        buf = self.container.buffer(spec.file)
        info: dict[str, Any] = {"sha256": sha256_of(buf), "bytes": buf.size}
        self._file_info[name] = info
        try:
            pf = pq.ParquetFile(pa.BufferReader(buf))
            info["kv"] = (pf.schema_arrow.metadata or {}).get(b"aveas")
            info["rows"] = pf.metadata.num_rows
            info["row_groups"] = pf.metadata.num_row_groups
            return checked(pf.read())
        except (pa.ArrowException, OSError) as e:
            self._unreadable(name, e)
            return None

    def _unreadable(self, name: str, e: Exception, prefix: str = "") -> None:
        """The table ``name`` could not be read (``e``: its first line is the finding's error)."""
        self.problem("unreadable_table", file=TABLES[name].file, table=name,
                     error=prefix + str(e).splitlines()[0])

    def _stream(self, name: str) -> bool:
        """Register ``name`` as streamed when it is large enough (and, for states, sorted by
        participant across row groups); its file info is taken from the footer and a chunked hash."""
        if not (name in _STREAMABLE or name.startswith(_STREAMABLE_PREFIX)):
            return False
        assert self.container is not None
        spec = TABLES[name]
        try:
            src = self.container.input_file(spec.file)
            pf = pq.ParquetFile(src)
        except (pa.ArrowException, OSError):
            return False  # read whole below, which reports the problem
        rows = pf.metadata.num_rows
        if rows <= self.config.streaming.above_rows:
            return False
        if name == "states" and not _participant_sorted(pf):
            return False  # read whole: structure.sort_order reports the order
        self._file_info[name] = {"sha256": self.container.sha256(spec.file),
                                 "bytes": src.size(), "rows": rows,
                                 "row_groups": pf.metadata.num_row_groups,
                                 "kv": (pf.schema_arrow.metadata or {}).get(b"aveas")}
        self.streamed[name] = Streamed(name, pf, rows, by_participant=name == "states")
        return True

    def _load_all(self) -> None:
        _ = self.meta
        _ = self._tables
        _ = self.map_bytes

    # -- map ----------------------------------------------------------------------------------
    @cached_property
    def map_bytes(self) -> bytes | None:
        if self.recording is not None:
            return self.recording.map_source
        assert self.container is not None
        name = self.meta_part("map").get("file") or "map.xodr"
        if not isinstance(name, str) or not self.container.exists(name):
            self.problem("missing_file", file=str(name))
            return None
        return self.container.read_bytes(name)

    # -- shared views for the semantic rules --------------------------------------------------
    @cached_property
    def participants_view(self):
        """:class:`~aveas_format.validate.views.ParticipantsView` of participants.parquet."""
        from aveas_format.validate.views import ParticipantsView

        prov = self.meta.provenance.value if self.meta is not None else None
        return ParticipantsView(self.table("participants"), prov)

    @cached_property
    def states_view(self):
        """:class:`~aveas_format.validate.views.StatesView` of states.parquet (None if absent or
        without usable participant_id / time)."""
        from aveas_format.validate.views import StatesView

        t = self.table("states")
        if t is None:
            return None
        v = StatesView(t, self.participants_view)
        return v if v.ok else None

    @cached_property
    def network(self):
        """The parsed map (RoadNetwork), or None when missing or unreadable (``map_unreadable``
        problem recorded)."""
        if self.recording is not None:
            try:
                return self.recording.map
            except Exception as e:  # noqa: BLE001 — reported by map.unreadable
                self.problem("map_unreadable", file=self.recording.meta.map.file,
                             error=str(getattr(e, "message", e)), line=getattr(e, "where", {}).get("line"))
                return None
        data = self.map_bytes
        if data is None:
            return None
        from aveas_format.opendrive import load_map

        name = self.meta_part("map").get("file") or "map.xodr"
        try:
            return load_map(data)
        except Exception as e:  # noqa: BLE001 — reported by map.unreadable
            self.problem("map_unreadable", file=str(name), error=str(getattr(e, "message", e)),
                         line=getattr(e, "where", {}).get("line"))
            return None

    @cached_property
    def frame(self):
        """The LocalFrame (crs + map offset), or None when the CRS cannot be read."""
        import warnings

        from aveas_format.errors import FormatError
        from aveas_format.crs import LocalFrame

        if self.meta is None:
            return None
        net = self.network
        offset = net.header.offset if net is not None else None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return LocalFrame(self.meta.crs, offset=offset, warn=False)
        except FormatError:
            return None
