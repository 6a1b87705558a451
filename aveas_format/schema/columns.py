"""Column and table declarations: the one place where each column of the format is declared.

A :class:`Column` states name, logical type, unit, allowed range, requirement level and doc. The
Arrow schemas (``aveas_format.io.arrow``), the machine-readable table spec (``aveas-format schema
--tables``), the generic structure rules of ``validate`` and ``docs/format.md`` are all derived from
these declarations (STYLE.md 9).

Logical types are small strings, so that this layer needs no pyarrow:

=================  ==========================================================
``int64``, ``int16``, ``int8``   signed integers
``float64``, ``float32``         IEEE floats
``bool``                         boolean
``string``                       UTF-8 string
``binary``                       bytes (WKB geometries)
``dict<string>``                 dictionary-encoded string (Parquet dictionary)
``list<int64>``, ``list<string>``  lists
``pmf<SET>``                     struct of float32 fields, one per category of ``SET``
                                 (see :data:`aveas_format.schema.taxonomy.CATEGORY_SETS`)
=================  ==========================================================
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from typing import Any

from aveas_format.schema.enums import Requirement
from aveas_format.schema.taxonomy import CATEGORY_SETS

_SCALAR_TYPES = {"int64", "int32", "int16", "int8", "float64", "float32", "bool", "string", "binary"}
_COMPOSITE_TYPES = {"dict<string>", "list<int64>", "list<string>"}
_PMF_RE = re.compile(r"^pmf<([a-z_]+)>$")


def _check_type(t: str) -> None:
    if t in _SCALAR_TYPES or t in _COMPOSITE_TYPES:
        return
    m = _PMF_RE.match(t)
    if not m:
        raise ValueError(f"unknown logical type {t!r}")
    if m.group(1) not in CATEGORY_SETS:
        raise ValueError(f"unknown PMF category set {m.group(1)!r} in {t!r}")


@dataclass(frozen=True)
class Column:
    """Declaration of one column of one table."""

    name: str
    type: str
    requirement: Requirement
    doc: str
    unit: str | None = None
    #: inclusive lower / upper bound of valid values (None = unbounded)
    minimum: float | None = None
    maximum: float | None = None
    #: when True the lower bound is exclusive (``> minimum``)
    exclusive_minimum: bool = False
    #: may the column hold nulls where it is present?
    nullable: bool = True
    #: allowed values of a ``dict<string>`` column (None = free text)
    categories: tuple[str, ...] | None = None
    #: a requirement that applies only under a condition, e.g. "measured" = provenance natural/staged
    condition: str | None = None
    #: for ``_std`` / ``_corr`` companions: the column(s) they qualify
    qualifies: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        _check_type(self.type)

    @property
    def pmf_set(self) -> str | None:
        """Name of the category set of a ``pmf<SET>`` column, else None."""
        m = _PMF_RE.match(self.type)
        return m.group(1) if m else None

    @property
    def pmf_categories(self) -> tuple[str, ...] | None:
        s = self.pmf_set
        return CATEGORY_SETS[s] if s else None

    @property
    def is_float(self) -> bool:
        return self.type in ("float64", "float32")

    def range_text(self) -> str:
        """The allowed range as text, e.g. ``> 0``, ``[0, 1]``, ``>= 0``; empty if unbounded."""
        lo, hi = self.minimum, self.maximum
        if lo is None and hi is None:
            return ""
        if hi is None:
            return f"{'>' if self.exclusive_minimum else '>='} {_num(lo)}"
        if lo is None:
            return f"<= {_num(hi)}"
        return f"{'(' if self.exclusive_minimum else '['}{_num(lo)}, {_num(hi)}]"

    def requirement_text(self) -> str:
        return f"{self.requirement.value} ({self.condition})" if self.condition else self.requirement.value

    def to_spec(self) -> dict[str, Any]:
        """A JSON-ready dict (the machine-readable table spec)."""
        d = asdict(self)
        d["requirement"] = self.requirement.value
        d["categories"] = list(self.categories) if self.categories else (
            list(self.pmf_categories) if self.pmf_categories else None
        )
        d["qualifies"] = list(self.qualifies)
        d["range"] = self.range_text() or None
        return d


def _num(v: float | None) -> str:
    return f"{v:g}" if v is not None else ""


@dataclass(frozen=True)
class TableSpec:
    """Declaration of one table (one Parquet file) of a recording."""

    name: str
    file: str
    requirement: Requirement
    doc: str
    columns: tuple[Column, ...]
    #: columns whose combination is unique
    key: tuple[str, ...] = ()
    #: sort order writers produce and readers may rely on
    sort: tuple[str, ...] = ()
    derived: bool = False
    _index: dict[str, Column] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        names = [c.name for c in self.columns]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ValueError(f"table {self.name}: duplicate columns {sorted(dup)}")
        self._index.update({c.name: c for c in self.columns})

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def column(self, name: str) -> Column:
        return self._index[name]

    def get(self, name: str) -> Column | None:
        return self._index.get(name)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns)

    @property
    def required(self) -> tuple[Column, ...]:
        """Columns that MUST be present (unconditionally)."""
        return tuple(c for c in self.columns if c.requirement is Requirement.MUST and not c.condition)

    def to_spec(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "file": self.file,
            "requirement": self.requirement.value,
            "doc": self.doc,
            "key": list(self.key),
            "sort": list(self.sort),
            "derived": self.derived,
            "columns": [c.to_spec() for c in self.columns],
        }


# --- helpers to declare columns ----------------------------------------------------------------

MUST, SHOULD, MAY = Requirement.MUST, Requirement.SHOULD, Requirement.MAY


def col(name: str, type: str, req: Requirement, doc: str, unit: str | None = None, **kw: Any) -> Column:
    return Column(name=name, type=type, requirement=req, doc=doc, unit=unit, **kw)


def std_of(name: str, unit: str | None, req: Requirement = MAY, condition: str | None = None,
           type: str = "float64") -> Column:
    """The Gaussian 1-sigma companion ``<name>_std`` of a real-valued column."""
    return Column(
        name=f"{name}_std", type=type, requirement=req, unit=unit, minimum=0.0, condition=condition,
        doc=f"1-sigma standard deviation of `{name}` (null = unknown, 0 = exact)", qualifies=(name,),
    )


def gaussian(name: str, unit: str | None, req: Requirement, doc: str, *,
             std_req: Requirement = MAY, std_condition: str | None = None, type: str = "float64",
             **kw: Any) -> list[Column]:
    """A real-valued column and its ``_std`` companion."""
    return [col(name, type, req, doc, unit, **kw), std_of(name, unit, std_req, std_condition, type)]


def corr(name: str, a: str, b: str, req: Requirement = MAY) -> Column:
    """A correlation column completing the 2x2 covariance of the pair (a, b)."""
    return Column(
        name=name, type="float32", requirement=req, minimum=-1.0, maximum=1.0, qualifies=(a, b),
        doc=f"correlation of `{a}` and `{b}`; with their `_std` it completes the 2x2 covariance",
    )


def prob(name: str, doc: str, req: Requirement = MAY) -> Column:
    """A binary state as the float32 probability ``*_p`` that it is on/true."""
    return Column(name=name, type="float32", requirement=req, minimum=0.0, maximum=1.0,
                  doc=f"probability that {doc}")


def pmf(name: str, set_name: str, req: Requirement, doc: str, condition: str | None = None) -> Column:
    cats = CATEGORY_SETS[set_name]
    return Column(name=name, type=f"pmf<{set_name}>", requirement=req, condition=condition,
                  doc=f"{doc}; struct of float32 fields {', '.join(cats)} (>= 0, sum 1)")


def enum_col(name: str, categories: tuple[str, ...], req: Requirement, doc: str, **kw: Any) -> Column:
    return Column(name=name, type="dict<string>", requirement=req, categories=categories,
                  doc=f"{doc}; one of {', '.join(categories)}", **kw)


def pid_col(doc: str = "participant, refers to participants.participant_id") -> Column:
    """The ``participant_id`` column of a per-participant table."""
    return col("participant_id", "int64", MUST, doc, minimum=0, nullable=False)


def time_col(doc: str = "seconds since recording.json:start_time") -> Column:
    """The ``time`` column of a time-series table."""
    return col("time", "float64", MUST, doc, "s", nullable=False)


def interval_cols(req: Requirement = MUST) -> list[Column]:
    """The ``time_start``/``time_end`` columns of a table of validity intervals."""
    return [
        col("time_start", "float64", req, "start of the validity interval", "s", nullable=False),
        col("time_end", "float64", req, "end of the validity interval (>= time_start)", "s",
            nullable=False),
    ]
