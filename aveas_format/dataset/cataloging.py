"""The catalog of a dataset: one row per recording (a :class:`pyarrow.Table`), built from
recording.json, the participants table, the ``ttc``/``pet`` columns of the derived tables and the
kinds of events (never whole states), to query with pyarrow, DuckDB or Polars (docs/datasets.md)."""

from __future__ import annotations

import contextlib
import functools
import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from aveas_format.dataset.discovery import local_copy, map_recordings
from aveas_format.dataset.report import read_facts_if_local, recording_facts
from aveas_format.parallel import TaskResult


#: the recording row of derived/criticality_summary in the catalog: catalog column <- summary column
SUMMARY_COLUMNS = {"min_ttc_std_s": "min_ttc_std", "min_ttc_time_s": "min_ttc_time",
                   "min_pet_std_s": "min_pet_std", "tet_s": "tet", "tet_std_s": "tet_std",
                   "tit_s2": "tit", "tit_std_s2": "tit_std", "cpi": "cpi", "cpi_std": "cpi_std",
                   "max_drac_mps2": "max_drac", "max_drac_std_mps2": "max_drac_std",
                   "min_psd": "min_psd", "min_psd_std": "min_psd_std"}


def _classes() -> list[str]:
    """The classes of the taxonomy, one ``n_CLASS`` column each in the catalog."""
    from aveas_format.schema.taxonomy import CLASSES

    return list(CLASSES)


def catalog_schema():
    """The pyarrow schema of the catalog (one row per recording)."""
    import pyarrow as pa

    fields = [
        ("path", pa.string()), ("recording_id", pa.string()), ("title", pa.string()),
        ("format_version", pa.string()), ("partner", pa.string()), ("method", pa.string()),
        ("provenance", pa.string()), ("site", pa.string()), ("country", pa.string()),
        ("road_type", pa.string()), ("start_time", pa.timestamp("ns", tz="UTC")),
        ("duration_s", pa.float64()), ("nominal_rate_hz", pa.float64()),
        ("lon", pa.float64()), ("lat", pa.float64()), ("crs", pa.string()),
        ("coverage_area_m2", pa.float64()), ("right_of_use", pa.string()),
        ("license", pa.string()), ("n_participants", pa.int64()), ("n_states", pa.int64()),
        ("participants_per_class", pa.map_(pa.string(), pa.int64())),
        *[(f"n_{c}", pa.int64()) for c in _classes()],
        ("tables", pa.list_(pa.string())), ("derived", pa.list_(pa.string())),
        ("size_bytes", pa.int64()),
        ("validated", pa.bool_()), ("valid", pa.bool_()), ("errors", pa.int64()),
        ("warnings", pa.int64()), ("infos", pa.int64()), ("rules_failed", pa.list_(pa.string())),
        ("min_ttc_s", pa.float64()), ("min_pet_s", pa.float64()), ("near_misses", pa.int64()),
        ("hard_braking", pa.int64()),
        *[(c, pa.float64()) for c in SUMMARY_COLUMNS],
        ("ttc_samples_below", pa.int64()), ("worst_events", pa.list_(pa.int64())),
        ("read_error", pa.string()),
    ]
    return pa.schema([pa.field(n, t) for n, t in fields])


def _size(path: str) -> int | None:
    p = Path(path)
    if p.is_file():
        return p.stat().st_size
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return None


def _finite_min(table: Any, column: str) -> float | None:
    import numpy as np

    if table is None or column not in table.column_names or not table.num_rows:
        return None
    a = table.column(column).to_numpy(zero_copy_only=False).astype(float)
    a = a[np.isfinite(a)]
    return float(a.min()) if a.size else None


def catalog_row(path: str, *, validate: bool = True, select: list[str] | None = None,
                ignore: list[str] | None = None, config: Any = None) -> dict[str, Any]:
    """One catalog row (a task): recording.json, the participants table, the footer of states,
    the ``ttc``/``pet`` columns of derived tables and the kinds of events — never whole states.
    ``validate=True`` runs the validator for the validity columns."""
    import numpy as np
    import pyarrow.compute as pc
    import shapely

    from aveas_format.io.container import Container
    from aveas_format.io.reader import open_recording, read_meta, table_names_present

    with local_copy(path) as local:
        with Container(local) as c:
            meta, _ = read_meta(c)
            present = table_names_present(c, meta)
        small = [t for t in ("participants", "derived/interactions", "derived/encroachments",
                             "events", "derived/criticality_summary") if t in present]
        rec = open_recording(local, tables=small, verify=False, columns={
            "derived/interactions": ["ttc"], "derived/encroachments": ["pet"],
            "events": ["kind", "origin"]})
        row: dict[str, Any] = {"path": path, **recording_facts(meta)}
        row.update(title=meta.title, format_version=meta.format_version,
                   start_time=meta.start_time, duration_s=meta.duration_s,
                   nominal_rate_hz=meta.nominal_rate_hz, lon=meta.location.lon,
                   lat=meta.location.lat, crs=meta.crs,
                   right_of_use=meta.rights.right_of_use.value, license=meta.rights.license,
                   tables=present, derived=[t for t in present if t.startswith("derived/")],
                   size_bytes=_size(local))
        area = None
        if meta.coverage:
            with contextlib.suppress(Exception):
                area = float(shapely.from_wkt(meta.coverage).area)
        row["coverage_area_m2"] = area
        entry = meta.tables.get("states")
        row["n_states"] = entry.rows if entry is not None else None
        p = rec.participants
        per_class: dict[str, int] = {}
        if p is not None and p.num_rows:
            for d in pc.value_counts(p.column("class").cast("string")).to_pylist():
                per_class[d["values"]] = int(d["counts"])
        row["n_participants"] = p.num_rows if p is not None else None
        row["participants_per_class"] = sorted(per_class.items())
        for cl in _classes():
            row[f"n_{cl}"] = per_class.get(cl, 0)
        row["min_ttc_s"] = _finite_min(rec.derived.get("interactions"), "ttc")
        row["min_pet_s"] = _finite_min(rec.derived.get("encroachments"), "pet")
        _summary_columns(row, rec.derived.get("criticality_summary"))
        ev = rec.events
        if ev is not None and ev.num_rows:
            kind = np.asarray(ev.column("kind").cast("string").to_pylist(), dtype=object)
            origin = np.asarray(ev.column("origin").cast("string").to_pylist(), dtype=object)
            der = origin == "derived"
            row["near_misses"] = int(((kind == "near_miss") & der).sum())
            row["hard_braking"] = int(((kind == "hard_braking") & der).sum())
        else:
            row["near_misses"] = row["hard_braking"] = 0
        row["validated"] = validate
        if validate:
            from aveas_format.validate.runner import validate as run

            rep = run(local, select=select, ignore=ignore, config=config, max_sample=1)
            c = rep.counts
            row.update(errors=c["error"], warnings=c["warning"], infos=c["info"],
                       valid=(not rep.failures and c["error"] == 0),
                       rules_failed=sorted(rep.codes | {f.code for f in rep.failures}))
    return row


def _summary_columns(row: dict[str, Any], cs: Any) -> None:
    """The catalog's criticality columns from the recording row of derived/criticality_summary
    (its minimum TTC, PET and counts are those of the whole recording, like the columns filled
    from derived/interactions and events)."""
    rec_row = None
    if cs is not None and cs.num_rows:
        rec_row = next((r for r in cs.to_pylist() if str(r["scope"]) == "recording"), None)
    for c, k in SUMMARY_COLUMNS.items():
        row[c] = None if rec_row is None else rec_row.get(k)
    row["ttc_samples_below"] = None if rec_row is None else rec_row.get("ttc_samples_below")
    row["worst_events"] = None if rec_row is None else rec_row.get("worst_events")


def catalog(paths: Iterable[str | Path], *, validate: bool = True, workers: int | None = 1,
            scheduler: str | None = None, progress: bool = False,
            select: list[str] | None = None, ignore: list[str] | None = None,
            on_result: Callable[[TaskResult], None] | None = None):
    """The catalog of a dataset as a :class:`pyarrow.Table` (schema :func:`catalog_schema`), one
    row per recording; a recording that cannot be read gets a row with ``read_error`` set."""
    import pyarrow as pa

    fn = functools.partial(catalog_row, validate=validate, select=select, ignore=ignore)
    rows = []
    for r in map_recordings(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                            progress=progress, description="catalog"):
        if on_result is not None:
            on_result(r)
        rows.append(r.value if r.ok else {"path": r.item, **read_facts_if_local(r.item),
                                          "read_error": r.error})
    rows.sort(key=lambda d: d["path"])
    schema = catalog_schema()
    cols = {f.name: [row.get(f.name) for row in rows] for f in schema}
    cols["start_time"] = [_ts(v) for v in cols["start_time"]]
    return pa.Table.from_pydict(cols, schema=schema)


def _ts(v: Any) -> Any:
    if v is None or not isinstance(v, str):
        return v
    from datetime import datetime

    return datetime.fromisoformat(v.replace("Z", "+00:00"))


def write_catalog(table: Any, path: str | Path) -> Path:
    """Write the catalog: Parquet (``.parquet``), CSV (``.csv``) or JSON lines (``.jsonl``)."""
    import pyarrow as pa

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    suffix = p.suffix.lower()
    if suffix == ".csv":
        import pyarrow.csv as pacsv

        flat = table.drop_columns(["participants_per_class", "tables", "derived", "rules_failed",
                                   "worst_events"])
        for name in ("tables", "derived", "rules_failed"):
            flat = flat.append_column(name, pa.array(
                [";".join(v) if v else None for v in table.column(name).to_pylist()], pa.string()))
        flat = flat.append_column("worst_events", pa.array(
            [";".join(map(str, v)) if v else None for v in table.column("worst_events").to_pylist()],
            pa.string()))
        pacsv.write_csv(flat, tmp)
    elif suffix in (".jsonl", ".ndjson"):
        with open(tmp, "w", encoding="utf-8") as f:
            for row in table.to_pylist():
                f.write(json.dumps(row, default=str) + "\n")
    else:
        import pyarrow.parquet as pq

        pq.write_table(table, tmp)
    os.replace(tmp, p)
    return p
