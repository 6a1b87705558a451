"""Metadata: recording.json against the data it describes (provenance, method, sensors, rights...).

The JSON Schema of recording.json is checked by structure.metadata_schema; these rules check what a
schema cannot: agreement between fields, with the tables, and placeholders that say nothing.
"""

from __future__ import annotations

import time as _time
from collections.abc import Iterator
from pathlib import Path

from aveas_format.schema.metadata import timestamp_ns
from aveas_format.schema.tables import TABLES
from aveas_format.schema.docs import quality
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, rule

_SIMULATION = {"traffic_simulation", "driving_simulator"}
#: sensor kinds that can produce the data of each acquisition method
_METHOD_SENSORS = {
    "road_vehicle": {"lidar", "rgb_camera", "lwir_camera", "radar", "gnss_imu"},
    "infrastructure_lidar": {"lidar"},
    "infrastructure_lwir": {"lwir_camera"},
    "infrastructure_camera": {"rgb_camera", "lwir_camera"},
    "aerial": {"rgb_camera", "lwir_camera", "lidar"},
    "accident_reconstruction": {"manual", "rgb_camera", "lidar", "gnss_imu", "radar", "lwir_camera"},
    "driving_simulator": {"simulator"},
    "traffic_simulation": {"simulator"},
}


@rule("metadata.provenance_mismatch", "error", "provenance disagrees with the participants",
      "recording.json: provenance is {value!r}, but the participants are {actual}",
      enforces="docs/format.md §3: provenance is natural, staged or simulated, or mixed (= the "
               "participants differ)")
def provenance_mismatch(ctx: Context) -> Iterator[Hit]:
    """recording.json ``provenance`` is natural, staged or simulated but a participant has another
    provenance, or it is ``mixed`` while all participants share one."""
    if ctx.meta is None:
        return
    pv = ctx.participants_view
    t = pv.table
    if t is None or "provenance" not in t.column_names or not pv.n:
        return
    kinds = sorted({p for p in pv.provenance if p is not None})
    rec = ctx.meta.provenance.value
    if not kinds:
        return
    if (rec == "mixed" and len(kinds) == 1) or (rec != "mixed" and kinds != [rec]):
        counts = {k: int((pv.provenance == k).sum()) for k in kinds}
        yield Hit(file="recording.json", column="provenance", value=rec,
                  actual=", ".join(f"{n} {k}" for k, n in counts.items()))


@rule("metadata.method_vs_provenance", "warning", "Acquisition method and provenance disagree",
      "recording.json: acquisition.method {method!r} with provenance {value!r}",
      enforces=quality("consistent_metadata"))
def method_vs_provenance(ctx: Context) -> Iterator[Hit]:
    """A simulation method (traffic_simulation, driving_simulator) with natural or staged
    provenance, or a measuring method with simulated provenance (a driving simulator's subject is
    the exception: its own participant may be natural, so ``mixed`` is accepted there)."""
    if ctx.meta is None:
        return
    m, p = ctx.meta.acquisition.method.value, ctx.meta.provenance.value
    bad = (m == "traffic_simulation" and p != "simulated") or \
        (m == "driving_simulator" and p not in ("simulated", "mixed")) or \
        (m not in _SIMULATION and p == "simulated")
    if bad:
        yield Hit(file="recording.json", column="provenance", method=m, value=p)


@rule("metadata.method_vs_sensors", "warning", "Sensors cannot produce data of this method",
      "recording.json: acquisition.method {method!r} but no sensor of a kind that produces it "
      "({expected}); sensors: {value}",
      enforces=quality("consistent_metadata"))
def method_vs_sensors(ctx: Context) -> Iterator[Hit]:
    """acquisition.sensors is not empty but lists no sensor of a kind that can produce the data of
    the acquisition method (e.g. ``infrastructure_lidar`` without a lidar, ``aerial`` with only a
    radar, a simulation without a ``simulator``)."""
    if ctx.meta is None:
        return
    acq = ctx.meta.acquisition
    kinds = {s.kind.value for s in acq.sensors}
    expected = _METHOD_SENSORS.get(acq.method.value, set())
    if kinds and expected and not (kinds & expected):
        yield Hit(file="recording.json", column="acquisition.sensors", method=acq.method.value,
                  expected=", ".join(sorted(expected)), value=", ".join(sorted(kinds)))


_SHOULD_FIELDS = (
    ("acquisition.platform", lambda m: m.acquisition.platform),
    ("acquisition.sensors", lambda m: m.acquisition.sensors),
    ("acquisition.not_observable", lambda m: m.acquisition.not_observable),
    ("acquisition.site", lambda m: m.acquisition.site),
    ("source", lambda m: m.source),
)


@rule("metadata.should_field_missing", "warning", "Recommended metadata field missing",
      "recording.json: {column} is missing (docs/format.md §3: SHOULD)",
      enforces=("docs/format.md §3: acquisition.platform, .sensors, .not_observable, .site and source "
                "SHOULD be given"))
def should_field_missing(ctx: Context) -> Iterator[Hit]:
    """A recording.json field that docs/format.md §3 marks SHOULD is absent or empty:
    acquisition.platform, .sensors, .not_observable, .site, and source (coverage: see
    unobserved.coverage_missing)."""
    if ctx.meta is None:
        return
    for name, get in _SHOULD_FIELDS:
        v = get(ctx.meta)
        if v is None or v == [] or v == "":
            yield Hit(file="recording.json", column=name)


def _placeholder(ctx: Context, v: str | None) -> bool:
    return v is None or v.strip().lower() in {p.lower() for p in ctx.config.metadata.placeholders}


@rule("metadata.rights_unclear", "warning", "Rights of use unclear",
      "recording.json: rights.{column_}: {why}",
      enforces=quality("clear_rights"))
def rights_unclear(ctx: Context) -> Iterator[Hit]:
    """``rights.license`` or ``rights.owner`` is a placeholder ("unknown", "unspecified", ...;
    ``[metadata] placeholders``), or ``right_of_use`` is commercial while the licence is a
    non-commercial one (…-NC-…): a consortium cannot share data whose rights are unclear."""
    if ctx.meta is None:
        return
    r = ctx.meta.rights
    for field in ("license", "owner"):
        v = getattr(r, field)
        if _placeholder(ctx, v):
            yield Hit(file="recording.json", column=f"rights.{field}", column_=field,
                      why=f"{v!r} is a placeholder")
    if r.right_of_use.value == "commercial" and "-NC" in r.license.upper():
        yield Hit(file="recording.json", column="rights.license", column_="license",
                  why=f"right_of_use is commercial but the licence {r.license!r} is non-commercial")


@rule("metadata.partner_placeholder", "warning", "Partner unknown",
      "recording.json: acquisition.partner {value!r} does not name an institution",
      enforces=quality("real_values"))
def partner_placeholder(ctx: Context) -> Iterator[Hit]:
    """``acquisition.partner`` is a placeholder ("unknown", ...): docs/format.md §3 requires the
    institution that acquired the data."""
    if ctx.meta is not None and _placeholder(ctx, ctx.meta.acquisition.partner):
        yield Hit(file="recording.json", column="acquisition.partner",
                  value=ctx.meta.acquisition.partner)


@rule("metadata.start_time_implausible", "warning", "start_time implausible",
      "recording.json: start_time {value} is {why}",
      enforces=quality("real_values"))
def start_time_implausible(ctx: Context) -> Iterator[Hit]:
    """``start_time`` lies before ``[metadata] earliest_start`` (1990; 1970-01-01 is an epoch
    default, not a date) or more than a day in the future. A simulation (provenance
    ``simulated``) has no calendar date: its time zero may be the epoch, only the future is
    flagged."""
    if ctx.meta is None:
        return
    ns = ctx.meta.start_time_ns
    earliest = ctx.config.metadata.earliest_start
    if ns < timestamp_ns(earliest) and ctx.meta.provenance.value != "simulated":
        yield Hit(file="recording.json", column="start_time", value=ctx.meta.start_time,
                  why=f"before {earliest}")
    elif ns > (_time.time() + 86400) * 1e9:
        yield Hit(file="recording.json", column="start_time", value=ctx.meta.start_time,
                  why="in the future")


@rule("metadata.derived_undocumented", "error", "Derived table not documented",
      "recording.json: {why}",
      enforces="docs/format.md §10: each derived table records its method, version and parameters in "
               "recording.json derived")
def derived_undocumented(ctx: Context) -> Iterator[Hit]:
    """A derived table is present without an entry in recording.json ``derived``, or an entry
    names a derived table that is not present."""
    if ctx.meta is None:
        return
    present = {n for n in ctx.table_names if n.startswith("derived/")}
    documented = set()
    for e in ctx.meta.derived:
        name = e.table if e.table.startswith("derived/") else f"derived/{e.table}"
        documented.add(name)
    for n in sorted(present - documented):
        yield Hit(file=f"{n}.parquet", table=n, column="derived",
                  why=f"{n} has no entry in derived (method, version, parameters)")
    for n in sorted(documented - present):
        yield Hit(file="recording.json", table=n, column="derived",
                  why=f"derived names {n}, which is not in the recording")


@rule("metadata.derived_stale", "warning", "Derived table is stale",
      "{file}: {table} is stale: {why}",
      enforces=("docs/format.md §10: a derived table becomes stale when its inputs change; it SHOULD "
                "be derived again"))
def derived_stale(ctx: Context) -> Iterator[Hit]:
    """A derived table was computed from inputs that have changed since (docs/format.md §10: it becomes
    stale), or with a method whose version has changed. Decided by
    ``aveas_format.derive.registry.stale_derived``; where the derivation package is not available,
    this rule finds nothing. Derived tables without a ``derived`` entry are left to
    metadata.derived_undocumented."""
    try:
        from aveas_format.derive.registry import stale_derived  # type: ignore[import-not-found]
    except ImportError:
        return
    if ctx.meta is None:
        return
    rec = ctx.recording
    if rec is None:  # a Recording over the tables already read (no second read of the files)
        from aveas_format.io.recording import Recording

        # a streamed table enters with its key columns only: staleness needs its row count and the
        # SHA-256 recording.json lists, not its values
        tables = {n: t for n in ctx.table_names
                  if (t := ctx.table(n) if n not in ctx.streamed else ctx.key_table(n)) is not None}
        try:
            rec = Recording(meta=ctx.meta, tables=tables, map_source=ctx.map_bytes,
                            path=Path(ctx.name))
        except (KeyError, ValueError):
            return
    undocumented = {n for n in ctx.table_names if n.startswith("derived/")} - {
        e.table if e.table.startswith("derived/") else f"derived/{e.table}" for e in ctx.meta.derived}
    res = stale_derived(rec)
    items = res.items() if isinstance(res, dict) else ((getattr(r, "table", r),
                                                          getattr(r, "reason", None))
                                                         for r in (res or []))
    for name, why in items:
        name = str(name)
        if name not in TABLES and f"derived/{name}" in TABLES:
            name = f"derived/{name}"
        if name in undocumented:
            continue  # metadata.derived_undocumented reports it
        file = TABLES[name].file if name in TABLES else name
        yield Hit(file=file, table=name, why=str(why or "an input changed since it was derived, "
                                                        "or its method's version did"))

