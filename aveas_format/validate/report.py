"""The validation report: findings with typed locations, grouped by rule (STYLE.md 2, 3, 5).

A :class:`Finding` never carries its location inside a string: ``row``, ``participant_id``,
``time``, ``column``... are fields, and the message is rendered from the rule's template and those
fields. The :class:`Report` groups findings per rule with the true total count and a bounded sample,
and keeps rules that crashed apart as tool failures.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
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


#: location fields shown as ``name=value`` by :meth:`Location.text` (file/line and x,y apart)
TEXT_FIELDS = ("table", "row", "participant_id", "time", "column", "road_id", "lane_id", "xpath",
               "frame", "uid", "json_path", "message_index", "object_id", "entity")


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
    # a submitted source file's own coordinates (findings of the import, ``source.*`` rules)
    frame: str | None = Field(None, description="OpenLABEL frame key")
    uid: str | None = Field(None, description="OpenLABEL object uid")
    json_path: str | None = Field(None, description="JSON path in the source file, e.g. "
                                  "$.openlabel.frames['12'].objects['3']")
    message_index: int | None = Field(None, description="0-based index of an OSI message")
    object_id: int | None = Field(None, description="OSI object id")
    entity: str | None = Field(None, description="OpenSCENARIO entity (ScenarioObject name)")

    def text(self) -> str:
        parts = []
        if self.file:
            parts.append(self.file + (f":{self.line}" if self.line is not None else ""))
        elif self.line is not None:
            parts.append(f"line={self.line}")
        for name in TEXT_FIELDS:
            v = getattr(self, name)
            if name == "table" and self.file is not None and self.file == f"{v}.parquet":
                continue  # the file says it
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
    count: int = Field(1, ge=1, description="instances the finding stands for (a source finding "
                       "about many objects names the first; the rule's count is the sum)")

    def get(self, key: str) -> Any:
        """A location field, or ``code``/``severity``/``message``, or a context value."""
        if key in ("code", "message", "count"):
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


class ReportModel(BaseModel):
    """The JSON document of a validation report (``validate --format json``; its JSON Schema is
    :func:`report_json_schema`). Users work with :class:`Report`, which wraps it."""

    model_config = ConfigDict(extra="forbid", title="Report")

    recording: str
    format_version: str | None = None
    tool_version: str
    rules_run: list[str] = Field(default_factory=list)
    results: list[RuleResult] = Field(default_factory=list)
    failures: list[ToolFailure] = Field(default_factory=list)
    seconds: float = 0.0
    #: tables validated in batches (too large to load whole) and their number of batches
    streamed: dict[str, int] = Field(default_factory=dict)


class ExitCode(int):
    """An exit code at the report's own threshold (an ``int``: ``--fail-on error`` for a
    :class:`Report`, the dataset's ``fail_on`` for a dataset report); call it with another
    threshold: ``report.exit_code("warning")`` (``report.exit_code()`` is the value itself)."""

    def __new__(cls, at: Callable[[str], int], fail_on: str = "error") -> ExitCode:
        self = super().__new__(cls, at(fail_on))
        self._at, self._fail_on = at, fail_on
        return self

    def __call__(self, fail_on: str | None = None) -> int:
        return int(self._at(fail_on or self._fail_on))


class Codes(set):
    """A set of rule codes; ``report.codes()`` (the former method) still gives it."""

    def __call__(self) -> Codes:
        return self


def _field(name: str, doc: str) -> property:
    return property(lambda self: getattr(self._model, name),
                    lambda self, value: setattr(self._model, name, value), doc=doc)


#: (column, pandas dtype) of :meth:`Report.to_pandas` after code, severity, title, message
_FRAME_LOCATION = {"file": "string", "table": "string", "row": "Int64", "participant_id": "Int64",
                   "time": "Float64", "column": "string", "x": "Float64", "y": "Float64",
                   "road_id": "string", "lane_id": "Int64", "xpath": "string", "line": "Int64",
                   "frame": "string", "uid": "string", "json_path": "string",
                   "message_index": "Int64", "object_id": "Int64", "entity": "string"}


class Report:
    """The result of validating one recording (``aveas_format.validate(...)``).

    Data: ``recording``, ``format_version``, ``tool_version``, ``rules_run``, ``results`` (one
    :class:`RuleResult` per rule with findings: the true count and a bounded sample), ``failures``
    (rules that crashed: tool failures, never findings), ``seconds``, ``streamed``. Facts, all
    properties: ``counts`` (findings per severity), ``max_severity``, ``codes`` (rules with
    findings), ``status`` and ``exit_code`` (at ``--fail-on error``; ``report.exit_code("warning")``
    for another threshold). Views: :meth:`findings`, :meth:`flatten`, :meth:`to_pandas`,
    :meth:`to_json` (the CLI's ``--format json``, read back by :meth:`from_json`).
    """

    __slots__ = ("_model",)

    def __init__(self, model: ReportModel | None = None, /, **fields: Any) -> None:
        self._model = model if model is not None else ReportModel(**fields)

    recording = _field("recording", "Path or name of the recording.")
    format_version = _field("format_version", "format_version of the recording, if readable.")
    tool_version = _field("tool_version", "aveas-format version that validated it.")
    rules_run = _field("rules_run", "Codes of the rules that ran.")
    results = _field("results", "Per rule with findings: RuleResult (count, sample), worst first.")
    failures = _field("failures", "Rules that crashed (ToolFailure): a bug of the tool.")
    seconds = _field("seconds", "Wall time of the validation.")
    streamed = _field("streamed", "Tables validated in batches -> number of batches.")

    # -- facts ---------------------------------------------------------------------------------
    @property
    def counts(self) -> dict[str, int]:
        """Findings per severity (true totals): ``{"error": 0, "warning": 3, "info": 0}``."""
        out = {s.value: 0 for s in Severity}
        for r in self.results:
            out[r.severity.value] += r.count
        return out

    @property
    def max_severity(self) -> Severity | None:
        """The most severe finding's severity (None without findings)."""
        sev = [r.severity for r in self.results if r.count]
        return max(sev, key=lambda s: s.rank) if sev else None

    @property
    def codes(self) -> Codes:
        """Codes of the rules with findings (a set)."""
        return Codes(r.code for r in self.results if r.count)

    @property
    def status(self) -> str:
        """``valid`` (no error), ``invalid`` (errors) or ``tool failure`` (a rule crashed)."""
        return "tool failure" if self.failures else ("invalid" if self.counts["error"] else "valid")

    @property
    def exit_code(self) -> ExitCode:
        """0 = nothing at/above ``fail_on``, 1 = findings, 3 = the tool failed (docs/cli.md):
        an int at ``fail_on="error"``; ``report.exit_code("warning")`` at another threshold."""
        return ExitCode(self._exit_code)

    def _exit_code(self, fail_on: str) -> int:
        return 3 if self.failures else findings_exit_code(self.results, fail_on)

    # -- views ---------------------------------------------------------------------------------
    def findings(self) -> list[Finding]:
        """Every sampled finding, rule by rule."""
        return [f for r in self.results for f in r.sample]

    def flatten(self, keys: tuple[str, ...] = ("code", "row", "participant_id")) -> list[list[Any]]:
        """The sampled findings as rows of the given keys (STYLE.md 5, as frictionless does)."""
        return [[f.get(k) for k in keys] for f in self.findings()]

    def to_pandas(self):  # -> pandas.DataFrame
        """The sampled findings as a DataFrame, one row per finding: ``code``, ``severity`` (an
        ordered categorical, so ``df[df.severity >= "warning"]`` works), ``title``, ``message``,
        the typed location (``file``, ``table``, ``row``, ``participant_id``, ``time``,
        ``column``, ``x``, ``y``, ``road_id``, ``lane_id``, ``xpath``, ``line``, and a submitted
        file's ``frame``, ``uid``, ``json_path``, ``message_index``, ``object_id``, ``entity``;
        nullable dtypes) and ``context`` (a dict of the other values of the message). Needs pandas
        (``pip install "aveas-format[pandas]"``)."""
        from aveas_format.errors import require

        pd = require("pandas", extra="pandas", what="Report.to_pandas")
        rows = [(r, f) for r in self.results for f in r.sample]
        data: dict[str, Any] = {
            "code": pd.array([f.code for _, f in rows], dtype="string"),
            "severity": pd.Categorical([f.severity.value for _, f in rows],
                                       categories=["info", "warning", "error"], ordered=True),
            "title": pd.array([r.title for r, _ in rows], dtype="string"),
            "message": pd.array([f.message for _, f in rows], dtype="string"),
        }
        for name, dtype in _FRAME_LOCATION.items():
            data[name] = pd.array([getattr(f.location, name) for _, f in rows], dtype=dtype)
        data["context"] = pd.Series([f.context for _, f in rows], dtype=object)
        return pd.DataFrame(data)

    def to_dict(self) -> dict[str, Any]:
        """The JSON report as plain Python objects."""
        return self._model.model_dump(mode="json")

    def to_json(self) -> str:
        """The JSON report (what ``validate --format json`` prints)."""
        return self._model.model_dump_json(indent=2)

    @classmethod
    def from_json(cls, text: str | bytes) -> Report:
        """A report read back from :meth:`to_json` (e.g. a file written by ``validate -o``)."""
        return cls(ReportModel.model_validate_json(text))

    # -- Python niceties -----------------------------------------------------------------------
    def __eq__(self, other: object) -> bool:
        return isinstance(other, Report) and self._model == other._model

    __hash__ = None  # type: ignore[assignment]  # mutable, like the model it wraps

    def __getstate__(self) -> dict[str, Any]:
        return {"model": self._model}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self._model = state["model"]

    def __repr__(self) -> str:
        c = self.counts
        top = sorted((r for r in self.results if r.count), key=lambda r: (-r.severity.rank, -r.count,
                                                                           r.code))[:3]
        tops = ", ".join(f"{r.code} ({r.count})" for r in top)
        more = len(self.codes) - len(top)
        tops += f", +{more} more rule{'s' if more != 1 else ''}" if more > 0 else ""
        fails = f", {len(self.failures)} tool failure(s)" if self.failures else ""
        return (f"<Report {self.recording!r}: {self.status.upper()}: {c['error']} errors, "
                f"{c['warning']} warnings, {c['info']} info{fails}"
                + (f"; top: {tops}" if tops else "") + ">")

    def _repr_html_(self) -> str:
        """Jupyter: the verdict and a table of the rules with findings."""
        import html

        rows = "".join(f"<tr><td><code>{html.escape(r.code)}</code></td><td>{r.severity.value}"
                       f"</td><td style='text-align:right'>{r.count}</td><td>"
                       f"{html.escape(r.title)}</td></tr>" for r in self.results)
        c = self.counts
        head = (f"<p><b>{html.escape(str(self.recording))}</b>: {self.status.upper()} — "
                f"{c['error']} errors, {c['warning']} warnings, {c['info']} info</p>")
        return head + (f"<table><tr><th>rule</th><th>severity</th><th>count</th><th>title</th>"
                       f"</tr>{rows}</table>" if rows else "")


def report_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of the JSON report (``validate --format json``)."""
    schema = ReportModel.model_json_schema(mode="serialization")
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "aveas-format validation report"
    schema["description"] = "The result of validating one recording."
    return schema
