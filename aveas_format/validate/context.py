"""What rules look at: a recording loaded leniently, with every loading problem kept as data.

``aveas_format.open`` raises on the first problem; validation instead wants to report all of them.
:class:`Context` reads recording.json and each table on first use and records what went wrong
(``problems``) for the structure rules to report, so later rules simply see ``None`` for what could
not be read.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq
from pydantic import ValidationError

from aveas_format.errors import FormatError
from aveas_format.io.container import Container, sha256_of
from aveas_format.io.recording import Recording
from aveas_format.safeio import load_json
from aveas_format.schema.metadata import RecordingMeta
from aveas_format.schema.tables import TABLES
from aveas_format.schema.versions import VersionError, migrate_meta


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
        """The table as stored (not cast), or None if absent or unreadable."""
        return self._tables.get(name)

    def file_info(self, name: str) -> dict[str, Any]:
        """sha256, bytes, rows, row_groups and the raw ``aveas`` key of a table's file."""
        _ = self._tables
        return self._file_info.get(name, {})

    @cached_property
    def _file_info(self) -> dict[str, dict[str, Any]]:
        return {}

    def _read(self, name: str) -> pa.Table | None:
        if self.recording is not None:
            return self.recording.table(name)
        assert self.container is not None
        spec = TABLES[name]
        if not self.container.exists(spec.file):
            self.problem("missing_file", file=spec.file, table=name)
            return None
        buf = self.container.buffer(spec.file)
        info: dict[str, Any] = {"sha256": sha256_of(buf), "bytes": buf.size}
        self._file_info[name] = info
        try:
            pf = pq.ParquetFile(pa.BufferReader(buf))
            info["kv"] = (pf.schema_arrow.metadata or {}).get(b"aveas")
            info["rows"] = pf.metadata.num_rows
            info["row_groups"] = pf.metadata.num_row_groups
            return pf.read()
        except (pa.ArrowException, OSError) as e:
            self.problem("unreadable_table", file=spec.file, table=name,
                         error=str(e).splitlines()[0])
            return None

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
        from aveas_format.georef import LocalFrame

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
