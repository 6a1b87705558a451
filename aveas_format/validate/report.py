"""The validation report: findings with typed locations, grouped by rule (STYLE.md 2, 3, 5).

A :class:`Finding` never carries its location inside a string: ``row``, ``participant_id``,
``time``, ``column``... are fields, and the message is rendered from the rule's template and those
fields. The :class:`Report` groups findings per rule with the true total count and a bounded sample,
and keeps rules that crashed apart as tool failures.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import Enum
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from aveas_format.numeric import fmt_num


class Severity(str, Enum):
    """error = a MUST of the format, warning = a SHOULD, info = no quality impact."""

    ERROR = "error"
    WARNING = "warning"
    INFO = "info"

    @property
    def rank(self) -> int:
        """The order of severities (error > warning > info), for sorting and ``--fail-on``."""
        return {"error": 3, "warning": 2, "info": 1}[self.value]


def findings_exit_code(results: Iterable[Any], fail_on: str = "error") -> int:
    """1 when a rule's results (anything with ``severity`` and ``count``: :class:`RuleResult`, a
    dataset entry's per-rule summary) hold findings at or above ``fail_on``, else 0 (``never``:
    always 0). One place for the single-recording and the dataset exit codes."""
    if fail_on == "never":
        return 0
    threshold = Severity(fail_on).rank
    return 1 if any(r.count and r.severity.rank >= threshold for r in results) else 0


class Location(BaseModel):
    """Where a finding is. Every field is optional; set those that apply."""

    model_config = ConfigDict(extra="forbid")

    file: str | None = None
    table: str | None = None
    row: int | None = Field(None, description="0-based row in the table's file order")
    participant_id: int | None = None
    time: float | None = None
    column: str | None = None
    x: float | None = None
    y: float | None = None
    road_id: str | None = None
    lane_id: int | None = None
    xpath: str | None = None
    line: int | None = Field(None, description="1-based line in a text file (JSON, XML)")

    def text(self) -> str:
        parts = []
        if self.file:
            parts.append(self.file + (f":{self.line}" if self.line is not None else ""))
        for name in ("table", "row", "participant_id", "time", "column", "road_id", "lane_id", "xpath"):
            v = getattr(self, name)
            if v is not None:
                parts.append(f"{name}={fmt_num(v)}")
        if self.x is not None and self.y is not None:
            parts.append(f"x,y={self.x:.2f},{self.y:.2f}")
        return " ".join(parts)


class Finding(BaseModel):
    model_config = ConfigDict(extra="forbid")

    code: str
    severity: Severity
    message: str
    location: Location = Field(default_factory=Location)
    context: dict[str, Any] = Field(default_factory=dict)

    def get(self, key: str) -> Any:
        """A location field, or ``code``/``severity``/``message``, or a context value."""
        if key in ("code", "message"):
            return getattr(self, key)
        if key == "severity":
            return self.severity.value
        if key in Location.model_fields:
            return getattr(self.location, key)
        return self.context.get(key)


class RuleResult(BaseModel):
    """Findings of one rule: the true total and a bounded sample."""

    model_config = ConfigDict(extra="forbid")

    code: str
    severity: Severity
    title: str
    count: int = 0
    sample: list[Finding] = Field(default_factory=list)
    truncated: bool = False
    seconds: float = 0.0


class ToolFailure(BaseModel):
    """A rule that raised: a failure of the tool, not a finding about the data."""

    model_config = ConfigDict(extra="forbid")

    code: str
    error: str
    traceback: str


class Report(BaseModel):
    """The result of validating one recording."""

    model_config = ConfigDict(extra="forbid")

    recording: str
    format_version: str | None = None
    tool_version: str
    rules_run: list[str] = Field(default_factory=list)
    results: list[RuleResult] = Field(default_factory=list)
    failures: list[ToolFailure] = Field(default_factory=list)
    seconds: float = 0.0
    #: tables validated in batches (too large to load whole) and their number of batches
    streamed: dict[str, int] = Field(default_factory=dict)

    @property
    def counts(self) -> dict[str, int]:
        out = {s.value: 0 for s in Severity}
        for r in self.results:
            out[r.severity.value] += r.count
        return out

    def findings(self) -> list[Finding]:
        """Every sampled finding, rule by rule."""
        return [f for r in self.results for f in r.sample]

    def flatten(self, keys: tuple[str, ...] = ("code", "row", "participant_id")) -> list[list[Any]]:
        """The sampled findings as rows of the given keys (STYLE.md 5, as frictionless does)."""
        return [[f.get(k) for k in keys] for f in self.findings()]

    def codes(self) -> set[str]:
        return {r.code for r in self.results if r.count}

    def max_severity(self) -> Severity | None:
        sev = [r.severity for r in self.results if r.count]
        return max(sev, key=lambda s: s.rank) if sev else None

    def exit_code(self, fail_on: str = "error") -> int:
        """0 = nothing at/above ``fail_on``, 1 = findings, 3 = the tool failed (ARCHITECTURE.md)."""
        return 3 if self.failures else findings_exit_code(self.results, fail_on)

    def to_json(self) -> str:
        return self.model_dump_json(indent=2)


def report_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the JSON report (``validate --format json``)."""
    schema = Report.model_json_schema(mode="serialization")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "aveas-format validation report"
    return schema
