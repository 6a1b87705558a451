"""The in-memory recording: metadata model + pyarrow Tables + a lazily parsed map."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.schema.metadata import RecordingMeta
from aveas_format.schema.tables import CORE_TABLES, TABLES

_CORE = tuple(t.name for t in CORE_TABLES)


class Recording:
    """One recording in memory.

    Attributes: ``meta`` (:class:`~aveas_format.schema.RecordingMeta`), the tables
    ``participants``, ``states``, ``unobserved``, ``events``, ``environment``, ``interior``
    (:class:`pyarrow.Table` or None), ``derived`` (``{"kinematics": Table, ...}``), ``map_source``
    (the bytes of map.xodr) and ``map`` (the parsed road network, loaded on first use: the one
    place where ``io`` reaches up into ``opendrive``, see docs/architecture.md). The local <-> WGS 84
    frame is :meth:`aveas_format.mapref.LocalFrame.of`.
    """

    participants: pa.Table | None
    states: pa.Table | None
    unobserved: pa.Table | None
    events: pa.Table | None
    environment: pa.Table | None
    interior: pa.Table | None

    def __init__(self, meta: RecordingMeta, tables: dict[str, pa.Table], map_source: bytes | None,
                 *, path: Path | None = None, migrated_from: str | None = None) -> None:
        self.meta = meta
        self.map_source = map_source
        self.path = path
        #: the format_version the recording had on disk when it was migrated in memory, else None
        self.migrated_from = migrated_from
        self.read_plan = None
        self._map = None
        for name in _CORE:
            setattr(self, name, None)
        self.derived: dict[str, pa.Table] = {}
        self.replace_tables(tables)

    # -- tables ------------------------------------------------------------------------------
    def replace_tables(self, tables: dict[str, pa.Table]) -> None:
        for name, table in tables.items():
            if name not in TABLES:
                raise KeyError(f"unknown table {name!r}; known: {sorted(TABLES)}")
            if name.startswith("derived/"):
                self.derived[name.split("/", 1)[1]] = table
            else:
                setattr(self, name, table)

    def tables(self) -> dict[str, pa.Table]:
        """Every table present, by its format name (``states``, ``derived/kinematics``...)."""
        out = {n: getattr(self, n) for n in _CORE if getattr(self, n) is not None}
        out.update({f"derived/{n}": t for n, t in self.derived.items()})
        return out

    def table(self, name: str) -> pa.Table | None:
        return self.tables().get(name)

    # -- map ---------------------------------------------------------------------------------
    @property
    def map(self):  # -> aveas_format.opendrive.RoadNetwork
        """The parsed OpenDRIVE map (parsed on first access)."""
        if self._map is None:
            if self.map_source is None:
                raise ValueError("this recording has no map")
            from aveas_format.errors import MapError
            from aveas_format.opendrive import load_map

            try:
                self._map = load_map(self.map_source)
            except MapError as e:  # name the recording's map file, keep the XML line
                where = f"{self.path}/{self.meta.map.file}" if self.path else self.meta.map.file
                raise MapError(e.message, path=where, **e.where) from None
        return self._map

    # -- geopandas ---------------------------------------------------------------------------
    def to_geopandas(self, columns: list[str] | None = None, *, classes: bool = True):
        """The states as a ``geopandas.GeoDataFrame``: one Point per row in the recording's CRS
        (``crs`` of recording.json; x/y moved by the map header's offset), the states' columns
        (or ``columns``) and each participant's ``class``. Needs ``aveas-format[geo]``."""
        from aveas_format.io.geodata import states_geodataframe

        return states_geodataframe(self, columns, classes=classes)

    def unobserved_geodataframe(self):
        """The unobserved regions as a ``geopandas.GeoDataFrame`` of polygons in the recording's
        CRS (empty when there are none). Needs ``aveas-format[geo]``."""
        from aveas_format.io.geodata import unobserved_geodataframe

        return unobserved_geodataframe(self)

    # -- I/O ---------------------------------------------------------------------------------
    def write(self, path: str | Path, *, overwrite: bool = False, form: str | None = None) -> Path:
        """Write atomically to ``path`` (``NAME.aveas`` directory or ``NAME.aveas.zip``)."""
        from aveas_format.io.writer import write_recording

        return write_recording(self, path, overwrite=overwrite, form=form)

    # -- summaries ---------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """Facts for ``aveas-format info``: participants per class, duration, rate, columns, coverage."""
        m = self.meta
        out: dict[str, Any] = {
            "recording_id": m.recording_id,
            "title": m.title,
            "path": str(self.path) if self.path else None,
            "format_version": m.format_version,
            "migrated_from": self.migrated_from,
            "start_time": m.start_time,
            "duration_s": m.duration_s,
            "nominal_rate_hz": m.nominal_rate_hz,
            "acquisition_method": m.acquisition.method.value,
            "partner": m.acquisition.partner,
            "provenance": m.provenance.value,
            "location": m.location.model_dump(exclude_none=True),
            "crs": m.crs,
            "map": m.map.model_dump(),
            "coverage": m.coverage,
            "tables": {n: t.num_rows for n, t in self.tables().items()},
        }
        p = self.participants
        if p is not None and p.num_rows:
            counts = pc.value_counts(p.column("class").cast(pa.string())).to_pylist()
            out["participants_per_class"] = {d["values"]: d["counts"] for d in
                                             sorted(counts, key=lambda d: -d["counts"])}
            out["participants"] = p.num_rows
        s = self.states
        if s is not None and s.num_rows:
            t = s.column("time").to_numpy()
            pid = s.column("participant_id").to_numpy()
            out["states"] = s.num_rows
            out["time_span_s"] = [float(np.nanmin(t)), float(np.nanmax(t))]
            out["observed_rate_hz"] = _median_rate(pid, t)
            out["columns"] = s.column_names
            out["column_coverage"] = {c: round(1.0 - s.column(c).null_count / s.num_rows, 4)
                                      for c in s.column_names}
            out["on_map_share"] = (round(1.0 - s.column("road_id").null_count / s.num_rows, 4)
                                   if "road_id" in s.column_names else None)
        return out

    def __repr__(self) -> str:
        tabs = ", ".join(f"{n}={t.num_rows}" for n, t in self.tables().items())
        return f"<Recording {self.meta.recording_id!r} {tabs}>"


def _median_rate(pid: np.ndarray, t: np.ndarray) -> float | None:
    """Median sampling rate over consecutive samples of the same participant."""
    if len(t) < 2:
        return None
    same = pid[1:] == pid[:-1]
    dt = (t[1:] - t[:-1])[same]
    dt = dt[dt > 0]
    return float(round(1.0 / np.median(dt), 6)) if len(dt) else None

