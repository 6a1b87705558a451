"""The rule registry: one declaration per rule, found by its code (STYLE.md 1, 6).

A rule is a generator function decorated with :func:`rule`, which declares its stable code
``<family>.<snake_case>``, severity, title, message template, doc and the docs/format.md sentence it
enforces. It yields :class:`Hit` (one finding) or :class:`Hits` (a vectorised batch: the true total
and arrays of location fields, of which the runner keeps a bounded sample). Rules never raise on
bad data; an exception is a tool failure.

:func:`load_rules` imports the rule modules of :mod:`aveas_format.validate.rules` and of installed
partner packages (entry-point group ``aveas_format.rules``) through :mod:`aveas_format.plugins`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format import plugins
from aveas_format.validate.report import Severity

#: ``family.snake_case``, or ``family.group.snake_case`` (``source.osi.missing_dimension``)
_CODE = re.compile(r"^[a-z]+\.(?:[a-z][a-z0-9_]*\.)?[a-z][a-z0-9_]*$")


@dataclass
class Hit:
    """One finding: location fields (file, table, row, participant_id, time, column, x, y, road_id,
    lane_id, xpath, line) and context values, all usable in the rule's message template."""

    fields: dict[str, Any]

    def __init__(self, **fields: Any) -> None:
        self.fields = fields


@dataclass
class Hits:
    """Many findings at once: ``total`` and per-finding arrays (only a sample is materialised).

    ``arrays`` maps a field name to an array of length >= the sample size (in file order);
    ``const`` holds fields shared by every finding of the batch.
    """

    total: int
    arrays: dict[str, Any]
    const: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def where(cls, mask: np.ndarray, arrays: dict[str, Any] | None = None, **const: Any) -> Hits:
        """Findings at the rows where ``mask`` is true; ``row`` is set from the mask's positions."""
        idx = np.flatnonzero(mask)
        out = {"row": idx}
        for k, v in (arrays or {}).items():
            out[k] = np.asarray(v)[idx]
        return cls(total=len(idx), arrays=out, const=const)


RuleFn = Callable[..., Iterator[Hit | Hits]]


@dataclass(frozen=True)
class Rule:
    code: str
    severity: Severity
    title: str
    message: str
    doc: str
    fn: RuleFn
    enforces: str | None = None  # the docs/format.md sentence behind an error / warning
    #: "recording": runs once on the whole recording; "rows": looks only within the rows of a table
    #: (and within one participant's trajectory), so it runs on each batch of a streamed table
    scope: str = "recording"
    #: collectors (see :func:`collector`) whose merged results the rule reads from ctx.collected
    needs: tuple[str, ...] = ()

    @property
    def family(self) -> str:
        return self.code.split(".", 1)[0]

    @property
    def groups(self) -> tuple[str, ...]:
        """What ``--select`` may name to pick the rule besides its code: the family, and for a
        three-part code its group (``source``, ``source.osi``)."""
        parts = self.code.split(".")
        return tuple(".".join(parts[:i]) for i in range(1, len(parts)))


REGISTRY: dict[str, Rule] = {}


_SCOPES = ("recording", "rows")


def rule(code: str, severity: str, title: str, message: str, enforces: str | None = None,
         scope: str = "recording", needs: tuple[str, ...] = ()) -> Callable[[RuleFn], RuleFn]:
    """Register a rule (decorator). The function's docstring is the rule's doc. The registry
    enforces its own docs (STYLE.md 6), for built-in and plugin rules alike: a unique code, a
    title, a message, a doc, and for an error the docs/format.md sentence it enforces.

    ``scope="rows"`` declares that the rule only looks within the rows it is given: per row, or
    within one participant's trajectory (the runner hands it every participant's samples in one
    batch). Such rules run on each batch when a large table is streamed (docs/validate.md,
    "Streaming"); the runner maps their ``row`` back to file rows. ``scope="recording"`` rules run
    once and must not read a streamed table's rows (``Context.table`` gives None for it; they use
    ``Context.schema``, ``num_rows``, ``key_table`` or a collector instead).
    """
    if not _CODE.match(code):
        raise ValueError(f"rule code {code!r} must look like 'family.snake_case' (or "
                         "'family.group.snake_case')")
    if code in REGISTRY:
        raise ValueError(f"rule code {code!r} registered twice: {REGISTRY[code].fn.__module__} has it")
    if scope not in _SCOPES:
        raise ValueError(f"rule {code}: scope must be one of {_SCOPES}")
    if not title or not message:
        raise ValueError(f"rule {code} needs a title and a message template")
    if severity in ("error", "warning") and not enforces:
        raise ValueError(f"rule {code}: an {severity} rule must name the "
                         f"{'MUST' if severity == 'error' else 'SHOULD'} it enforces (enforces=...)")
    if severity == "warning" and "SHOULD" not in enforces:
        raise ValueError(f"rule {code}: a warning enforces a SHOULD; enforces={enforces!r} names none")

    def register(fn: RuleFn) -> RuleFn:
        doc = " ".join((fn.__doc__ or "").split())
        if not doc:
            raise ValueError(f"rule {code} has no doc")
        REGISTRY[code] = Rule(code=code, severity=Severity(severity), title=title, message=message,
                              doc=doc, fn=fn, enforces=enforces, scope=scope, needs=tuple(needs))
        return fn

    return register


@dataclass(frozen=True)
class Collector:
    """Gathers a compact summary of the states batch by batch for a ``recording`` rule that needs
    all participants at once (e.g. pairs of participants at the same time): ``collect(ctx)``
    runs on each context holding states rows and returns a partial (or None); ``merge(partials)``
    combines them and is stored in ``ctx.collected[key]``."""

    key: str
    collect: Callable[[Any], Any]
    merge: Callable[[list[Any]], Any]


COLLECTORS: dict[str, Collector] = {}


def collector(key: str, merge: Callable[[list[Any]], Any]) -> Callable[[Callable], Callable]:
    """Register a collector (decorator on its ``collect`` function)."""
    if key in COLLECTORS:
        raise ValueError(f"collector {key!r} registered twice")

    def register(fn: Callable) -> Callable:
        COLLECTORS[key] = Collector(key=key, collect=fn, merge=merge)
        return fn

    return register


def load_rules() -> dict[str, Rule]:
    """Every rule, built-in and of plugins (their modules register themselves on import)."""
    plugins.load("rules")
    return REGISTRY


def select_rules(select: list[str] | None = None, ignore: list[str] | None = None) -> list[Rule]:
    """Rules matching ``select`` (codes, families or groups such as ``source.osi``; default all)
    minus ``ignore``, by code (the
    same order whichever rule module happened to be imported first).

    Raises ValueError naming an unknown code or family.
    """
    reg = load_rules()
    families = {g for r in reg.values() for g in r.groups}

    def match(r: Rule, pats: list[str]) -> bool:
        return any(p == r.code or p in r.groups for p in pats)

    for p in (select or []) + (ignore or []):
        if p not in reg and p not in families:
            from aveas_format.errors import did_you_mean

            raise ValueError(f"unknown rule or family {p!r}{did_you_mean(p, [*families, *reg])}; "
                             f"families: {', '.join(sorted(families))}")
    chosen = [reg[c] for c in sorted(reg) if not select or match(reg[c], select)]
    return [r for r in chosen if not ignore or not match(r, ignore)]
