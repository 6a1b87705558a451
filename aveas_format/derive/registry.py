"""The registry of derivations and the ``derive`` driver (FORMAT.md section 10).

A :class:`Derivation` declares its ``name``, the table it writes (the spec of its derived table,
which :func:`register` adds to :data:`aveas_format.schema.tables.TABLES`), the columns it needs from
which tables, the derivations it builds on, a version, a pydantic parameter model and a function
``(rec, params) -> pyarrow.Table``. The derivation modules of this package and of installed partner
packages (entry-point group ``aveas_format.derivations``) are imported through
:mod:`aveas_format.plugins`; each registers itself with ``register(Derivation(...))``.

:func:`derive` runs the requested derivations (and any missing prerequisite) in dependency order,
stores each result in ``rec.derived`` (or ``rec.events``) and records method, version, parameters
and the SHA-256 of every input table in ``rec.meta.derived`` and in the table's own schema metadata
(``aveas_derived``). :func:`stale_derived` compares those hashes with the recording's current
tables.

>>> import aveas_format
>>> from aveas_format.derive import derive
>>> rec = aveas_format.open("highway.aveas")                          # doctest: +SKIP
>>> derive(rec, only=["kinematics"], kinematics={"jerk_density": 2.0})  # doctest: +SKIP
>>> rec.derived["kinematics"].column_names                           # doctest: +SKIP
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any

import pyarrow as pa
from pydantic import BaseModel, ConfigDict, ValidationError

from aveas_format import plugins
from aveas_format.errors import FormatError
from aveas_format.schema.columns import TableSpec
from aveas_format.schema.tables import TABLES, register_table

#: schema-metadata key of a derived table that carries how it was made
DERIVED_KEY = b"aveas_derived"


class Params(BaseModel):
    """Base class of derivation parameters (strict: unknown fields are an error)."""

    model_config = ConfigDict(extra="forbid", frozen=True)


@dataclass(frozen=True, kw_only=True)
class Derivation:
    """Declaration of one derivation.

    ``spec`` declares the derived table it writes (made with
    :func:`~aveas_format.schema.tables.derived_table`); ``table`` is then its name. A derivation of
    events leaves ``spec`` out and writes ``table="events"``. ``needs`` maps an input table
    (``states``, ``participants``, ``derived/kinematics``...) to the columns it must have;
    ``optional`` lists input tables used when present. ``after`` names the derivations whose tables
    it reads (they run first). ``method`` returns the method name for the given parameters (e.g.
    ``ca_kalman_rts`` or ``savitzky_golay``).
    """

    name: str
    version: str
    params: type[Params]
    fn: Callable[[Any, Any], pa.Table]
    needs: Mapping[str, tuple[str, ...]]
    doc: str
    spec: TableSpec | None = None
    table: str = ""
    after: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()
    method: Callable[[Any], str] = field(default=lambda p: "default")

    def __post_init__(self) -> None:
        if self.spec is not None:
            if self.table and self.table != self.spec.name:
                raise ValueError(f"derivation {self.name}: table {self.table!r} is not its spec's "
                                 f"{self.spec.name!r}")
            object.__setattr__(self, "table", self.spec.name)
        elif self.table != "events":
            raise ValueError(f"derivation {self.name}: declare the derived table it writes "
                             "(spec=derived_table(...)); events is the one core table a derivation "
                             "writes")

    def inputs(self) -> tuple[str, ...]:
        """Every table this derivation reads (required and optional)."""
        return tuple(self.needs) + tuple(t for t in self.optional if t not in self.needs)


REGISTRY: dict[str, Derivation] = {}


def register(d: Derivation) -> Derivation:
    """Add a derivation to :data:`REGISTRY` and the spec of its table to the schema's tables (its
    name and its table must be new)."""
    here = d.fn.__module__
    if d.name in REGISTRY:
        raise ValueError(f"derivation {d.name!r} of {here} is already registered: "
                         f"{REGISTRY[d.name].fn.__module__} has it")
    owner = next((o for o in REGISTRY.values() if o.table == d.table), None)
    if owner is not None:
        raise ValueError(f"derivation {d.name!r} of {here} writes {d.table}, which derivation "
                         f"{owner.name!r} of {owner.fn.__module__} writes")
    if d.spec is not None:
        register_table(d.spec)
    REGISTRY[d.name] = d
    return d


def _load() -> dict[str, Derivation]:
    """Every derivation, built-in and of plugins (their modules register themselves on import)."""
    plugins.load("derivations")
    return REGISTRY


def derivations() -> dict[str, Derivation]:
    """All registered derivations by name, in dependency order."""
    reg = _load()
    return {n: reg[n] for n in _order(sorted(reg))}


def _order(names: list[str]) -> list[str]:
    """Topological order of ``names`` and their prerequisites (stable, registry order)."""
    reg = REGISTRY
    out: list[str] = []
    seen: set[str] = set()

    def visit(n: str, stack: tuple[str, ...]) -> None:
        if n in seen:
            return
        if n in stack:
            raise ValueError(f"derivation cycle: {' -> '.join((*stack, n))}")
        for dep in reg[n].after:
            visit(dep, (*stack, n))
        seen.add(n)
        out.append(n)

    for n in names:
        visit(n, ())
    return out


# --- table access and hashes ---------------------------------------------------------------------

def get_table(rec, name: str) -> pa.Table | None:
    """A table of ``rec`` by format name (``states``, ``derived/kinematics``...), or None."""
    if name.startswith("derived/"):
        return rec.derived.get(name.split("/", 1)[1])
    return getattr(rec, name, None)


def table_sha256(rec, name: str) -> str | None:
    """SHA-256 of table ``name`` as it is (or would be) written: the value of recording.json
    ``tables`` when the recording was read or written and the table is unchanged since, otherwise
    computed from the table's canonical Parquet serialisation (the writer's)."""
    from aveas_format.io.container import sha256_of
    from aveas_format.io.writer import parquet_bytes, prepare_table

    t = get_table(rec, name)
    if t is None:
        return None
    cache = rec.__dict__.setdefault("_derive_sha_cache", {})
    hit = cache.get(name)
    if hit is not None and hit[0] is t:
        return hit[1]
    entry = rec.meta.tables.get(name)
    written = getattr(rec, "path", None) is not None and entry is not None and entry.rows == t.num_rows
    if written and name not in getattr(rec, "_derive_touched", set()):
        sha = entry.sha256
    else:
        spec = TABLES[name]
        sha = sha256_of(parquet_bytes(prepare_table(t, spec), spec))
    cache[name] = (t, sha)
    return sha


def check_columns(table: pa.Table | None, name: str, columns: Iterable[str], who: str) -> pa.Table:
    """``table`` if it has ``columns``; FormatError naming the derivation, table and column."""
    if table is None:
        raise FormatError(f"derivation {who}: table {name} is missing")
    missing = [c for c in columns if c not in table.column_names]
    if missing:
        raise FormatError(f"derivation {who}: table {name} lacks column(s) {', '.join(missing)}")
    return table


# --- the driver --------------------------------------------------------------------------------------

def _params_for(d: Derivation, per: Mapping[str, Any], flat: Mapping[str, Any],
                used: set[str]) -> Params:
    given = per.get(d.name)
    if isinstance(given, Params):
        if not isinstance(given, d.params):
            raise TypeError(f"parameters for {d.name} must be {d.params.__name__}")
        base = given.model_dump()
    else:
        base = dict(given or {})
    for k, v in flat.items():
        if k in d.params.model_fields:
            base.setdefault(k, v)
            used.add(k)
    try:
        return d.params(**base)
    except ValidationError as e:
        first = e.errors()[0]
        loc = ".".join(str(x) for x in first["loc"])
        raise FormatError(f"derivation {d.name}: parameter {loc}: {first['msg']}") from None


def empty_table(name: str) -> pa.Table:
    """A zero-row table of the required columns of derived table ``name``."""
    from aveas_format.io.arrow import arrow_schema

    spec = TABLES[name]
    return arrow_schema(spec, [c.name for c in spec.required]).empty_table()


def derive(rec, only: str | Iterable[str] | None = None, **params: Any) -> list[str]:
    """Run derivations on ``rec`` in dependency order; return the names of those run.

    only: a derivation name or names (default: all). Prerequisites that are missing from
    ``rec.derived`` are run too. params: either ``NAME={...}`` (a dict or the derivation's
    parameter model) or a plain keyword, which goes to every selected derivation that has a
    parameter of that name (a keyword no derivation knows is an error).

    Results go to ``rec.derived[NAME]`` (events: merged into ``rec.events``, replacing earlier
    derived events); ``rec.meta.derived`` gets one :class:`DerivedEntry` per table (replacing the
    previous entry of that table).
    """
    reg = _load()
    if only is None:
        wanted = sorted(reg)
    else:
        wanted = [only] if isinstance(only, str) else list(only)
        unknown = [n for n in wanted if n not in reg]
        if unknown:
            raise FormatError(f"unknown derivation(s) {', '.join(unknown)}; known: "
                              f"{', '.join(sorted(reg))}")
    per = {k: v for k, v in params.items() if k in reg}
    flat = {k: v for k, v in params.items() if k not in reg}
    order = _order(wanted)
    run = [n for n in order if n in wanted or get_table(rec, reg[n].table) is None
           or reg[n].table == "events"]
    # events is a core table that may exist without derived events: run a prerequisite
    # "events" only when asked for
    run = [n for n in run if n in wanted or reg[n].table != "events"]
    used: set[str] = set()
    resolved = {n: _params_for(reg[n], per, flat, used) for n in run}
    unused = sorted(set(flat) - used)
    if unused:
        raise FormatError(f"unknown parameter(s) {', '.join(unused)} for derivation(s) "
                          f"{', '.join(run)}")
    from aveas_format.schema.metadata import DerivedEntry

    for n in run:
        d = reg[n]
        p = resolved[n]
        for tname, cols in d.needs.items():
            check_columns(get_table(rec, tname), tname, cols, n)
        inputs = {t: table_sha256(rec, t) for t in d.inputs() if get_table(rec, t) is not None}
        if not rec.states.num_rows and d.table != "events":
            table = empty_table(d.table)  # nothing to derive from: an empty table, documented as usual
        else:
            table = d.fn(rec, p)
        method = d.method(p)
        pdump = p.model_dump(mode="json")
        info = {"derivation": n, "method": method, "version": d.version, "parameters": pdump,
                "inputs": inputs}
        md = dict(table.schema.metadata or {})
        md[DERIVED_KEY] = json.dumps(info).encode()
        table = table.replace_schema_metadata(md)
        if d.table == "events":
            rec.events = table
        else:
            rec.derived[d.table.split("/", 1)[1]] = table
        rec.__dict__.setdefault("_derive_touched", set()).add(d.table)
        if d.table == "events":
            # recording.json ``derived`` documents derived *tables*; derived events carry the same
            # facts in the events table's schema metadata and in each event's attributes
            rec.meta.derived = [e for e in rec.meta.derived if e.table != d.table]
            continue
        entry = DerivedEntry(table=d.table, method=method, version=d.version, parameters=pdump,
                             created=datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
                             inputs={k: v for k, v in inputs.items() if v is not None})
        rec.meta.derived = [e for e in rec.meta.derived if e.table != d.table] + [entry]
    return run


def stale_derived(rec) -> list[str]:
    """Names of the derived tables of ``rec`` that are stale: an input table changed (its SHA-256
    differs from the one recorded in ``recording.json:derived``) or disappeared, the derivation's
    version changed, or a derived table has no ``derived`` entry at all. ``events`` is listed when
    its derived events are stale (their inputs are recorded in the events table's schema metadata
    under ``aveas_derived``, since recording.json ``derived`` documents derived tables only)."""
    reg = _load()
    by_table = {d.table: d for d in reg.values()}
    entries = {e.table: e for e in rec.meta.derived}
    present = [f"derived/{n}" for n in rec.derived]
    out: list[str] = []
    for name in present:
        if name not in entries:
            out.append(name)
    for tname, e in entries.items():
        if get_table(rec, tname) is None:
            continue
        d = by_table.get(tname)
        if d is not None and d.version != e.version:
            out.append(tname)
            continue
        for inp, sha in e.inputs.items():
            if table_sha256(rec, inp) != sha:
                out.append(tname)
                break
    ev = rec.events
    raw = (ev.schema.metadata or {}).get(DERIVED_KEY) if ev is not None else None
    if raw:
        try:
            info = json.loads(raw)
        except (json.JSONDecodeError, UnicodeDecodeError):
            info = None
        d = reg.get("events")
        if not isinstance(info, dict) or (d is not None and info.get("version") != d.version):
            out.append("events")
        else:
            for inp, sha in (info.get("inputs") or {}).items():
                if sha is not None and table_sha256(rec, inp) != sha:
                    out.append("events")
                    break
    return sorted(set(out))


__all__ = ["DERIVED_KEY", "Derivation", "Params", "REGISTRY", "derivations", "derive", "register",
           "stale_derived", "table_sha256"]
