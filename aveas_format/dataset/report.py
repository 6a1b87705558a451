"""The dataset report: typed per-recording entries and their aggregate over a dataset.

Every batch operation (validate, derive, convert) returns one entry per recording that completed,
a :class:`RecordingEntry` (the operation's subclass: ``ValidationEntry``, ``DerivationEntry``,
``ConversionEntry``), and one :class:`FailedRecording` per recording that raised or crashed its
worker. :class:`DatasetReport` aggregates them (per rule, per partner, the worst recordings) and
renders JSON, text and HTML; :func:`run_dataset` maps a task over a dataset and collects one.

Entries are small, picklable pydantic models: they travel back from worker processes and Dask.
Severities are the validator's :class:`~aveas_format.validate.report.Severity`, ranked by its own
``rank``. In the JSON, an entry holds the fields its task set: a recording whose recording.json
cannot be read has no ``recording_id``, ``partner``... keys (rather than nulls), and only validation
entries have ``tool_failures``.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from collections.abc import Callable, Iterable
from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from aveas_format._version import __version__
from aveas_format.dataset.discovery import is_url
from aveas_format.dataset.html import render_dataset_html
from aveas_format.parallel import TaskResult, run_tasks
from aveas_format.validate.report import ExitCode, RuleResult, Severity, findings_exit_code

# ------------------------------------------------------------------------------------------
# facts from recording.json


def recording_facts(meta: Any) -> dict[str, str | None]:
    """partner, method, provenance, site... of a recording's metadata (``RecordingMeta``): the
    keys of dataset filters and groupings, and the facts of every entry."""
    site = meta.acquisition.site
    return {
        "recording_id": meta.recording_id, "partner": meta.acquisition.partner,
        "method": meta.acquisition.method.value, "provenance": meta.provenance.value,
        "site": site.name if site else None, "country": site.country if site else None,
        "road_type": site.road_type.value if site and site.road_type else None,
    }


def read_facts(path: str) -> dict[str, str | None]:
    """:func:`recording_facts` from recording.json only (cheap); {} when it cannot be read."""
    from aveas_format.io.container import Container
    from aveas_format.io.reader import read_meta

    try:
        with Container(path) as c:
            meta, _ = read_meta(c)
    except Exception:  # noqa: BLE001 — the caller reports the recording's real error
        return {}
    return recording_facts(meta)


def read_facts_if_local(item: Any) -> dict[str, str | None]:
    """:func:`read_facts` of a local recording path; {} for a URL or another task item."""
    if not isinstance(item, str) or is_url(item):
        return {}
    return read_facts(item)


# ------------------------------------------------------------------------------------------
# entries


class RuleCount(BaseModel):
    """The per-rule summary of one recording: how many findings one rule had."""

    model_config = ConfigDict(extra="forbid")

    code: str
    severity: Severity
    title: str
    count: int

    @classmethod
    def of(cls, result: RuleResult) -> RuleCount:
        return cls(code=result.code, severity=result.severity, title=result.title,
                   count=result.count)


class ToolFailureSummary(BaseModel):
    """A rule that crashed on a recording (the validator's ``ToolFailure`` without traceback)."""

    model_config = ConfigDict(extra="forbid")

    code: str
    error: str


class RecordingRef(BaseModel):
    """A recording of a dataset: its path (or URL, or conversion name) and, when recording.json
    could be read, its facts (:func:`recording_facts`)."""

    model_config = ConfigDict(extra="forbid")

    path: str
    recording_id: str | None = None
    partner: str | None = None
    method: str | None = None
    provenance: str | None = None
    site: str | None = None
    country: str | None = None
    road_type: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The JSON form: the fields the task set (see the module docstring)."""
        return self.model_dump(mode="json", exclude_unset=True)


class RecordingEntry(RecordingRef):
    """One recording that completed: its findings by severity and by rule, and rules that crashed
    on it. Each batch operation extends it with what it produced."""

    counts: dict[str, int] = Field(default_factory=dict)
    rules: list[RuleCount] = Field(default_factory=list)
    tool_failures: list[ToolFailureSummary] = Field(default_factory=list)

    def exit_code(self, fail_on: str = "error") -> int:
        """3 if a rule crashed on it, 1 if it has findings at/above ``fail_on``, else 0."""
        return 3 if self.tool_failures else findings_exit_code(self.rules, fail_on)


class FailedRecording(RecordingRef):
    """A recording whose task raised, or crashed its worker."""

    error: str
    traceback: str | None = None


class RuleTotal(BaseModel):
    """The per-rule summary over a dataset: findings and recordings with findings."""

    model_config = ConfigDict(extra="forbid")

    severity: Severity
    title: str
    count: int = 0
    recordings: int = 0


# ------------------------------------------------------------------------------------------
# the aggregate


class DatasetReport:
    """The aggregate of many recordings' outcomes (validation or another batch operation).

    ``entries`` holds one :class:`RecordingEntry` per recording that completed, ``failed`` one
    :class:`FailedRecording` per recording that raised or crashed its worker.
    """

    def __init__(self, kind: str = "validate", specs: list[str] | None = None,
                 fail_on: str = "error") -> None:
        self.kind = kind
        self.specs = specs or []
        self.fail_on = fail_on
        self.entries: list[RecordingEntry] = []
        self.failed: list[FailedRecording] = []
        self.seconds = 0.0
        self.runner: dict[str, Any] = {}

    def add(self, r: TaskResult) -> None:
        if r.ok:
            self.entries.append(r.value)
        else:
            self.failed.append(FailedRecording(path=str(r.item), **read_facts_if_local(r.item),
                                               error=r.error, traceback=r.traceback))

    # -- aggregates --------------------------------------------------------------------------
    @property
    def recordings(self) -> int:
        return len(self.entries) + len(self.failed)

    @property
    def counts(self) -> dict[str, int]:
        out = {s.value: 0 for s in Severity}
        for e in self.entries:
            for k, v in e.counts.items():
                out[k] = out.get(k, 0) + v
        return out

    @property
    def max_severity(self) -> Severity | None:
        """The most severe finding's severity over the dataset (None without findings)."""
        sev = [r.severity for e in self.entries for r in e.rules if r.count]
        return max(sev, key=lambda s: s.rank) if sev else None

    @property
    def exit_code(self) -> ExitCode:
        """The worst over the dataset: 3 if any recording failed (unreadable, crashed, tool
        failure), else 1 if any has findings at/above ``fail_on``, else 0. An int at the
        report's ``fail_on``; ``rep.exit_code("warning")`` at another threshold (as
        :attr:`Report.exit_code <aveas_format.validate.report.Report.exit_code>`)."""
        return ExitCode(self._exit_code, self.fail_on)

    def _exit_code(self, fail_on: str) -> int:
        if self.failed or any(e.tool_failures for e in self.entries):
            return 3
        return max((e.exit_code(fail_on) for e in self.entries), default=0)

    def by_rule(self) -> dict[str, RuleTotal]:
        """Per rule, worst first (severity, then findings, then code)."""
        out: dict[str, RuleTotal] = {}
        for e in self.entries:
            for r in e.rules:
                t = out.setdefault(r.code, RuleTotal(severity=r.severity, title=r.title))
                t.count += r.count
                t.recordings += 1 if r.count else 0
        return dict(sorted(out.items(), key=lambda kv: (-kv[1].severity.rank, -kv[1].count,
                                                        kv[0])))

    def by_partner(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}

        def slot(p: str | None) -> dict[str, Any]:
            return out.setdefault(p or "(unknown)", {"recordings": 0, "failed": 0, "valid": 0,
                                                      "error": 0, "warning": 0, "info": 0,
                                                      "rules": {}})
        for e in self.entries:
            d = slot(e.partner)
            d["recordings"] += 1
            d["valid"] += 1 if e.exit_code(self.fail_on) == 0 else 0
            for k, v in e.counts.items():
                d[k] = d.get(k, 0) + v
            for r in e.rules:
                d["rules"][r.code] = d["rules"].get(r.code, 0) + r.count
        for f in self.failed:
            d = slot(f.partner)
            d["recordings"] += 1
            d["failed"] += 1
        return dict(sorted(out.items()))

    def worst(self, n: int = 10) -> list[dict[str, Any]]:
        """The ``n`` worst recordings: failed first, then by errors, warnings, infos."""
        rows = [{"path": f.path, "recording_id": f.recording_id, "partner": f.partner,
                 "status": "failed", "error": f.error, "counts": None} for f in self.failed]
        scored = sorted(self.entries, key=lambda e: (-bool(e.tool_failures),
                                                     -e.counts.get("error", 0),
                                                     -e.counts.get("warning", 0),
                                                     -e.counts.get("info", 0), e.path))
        for e in scored:
            if not any(e.counts.values()) and not e.tool_failures:
                continue
            rows.append({"path": e.path, "recording_id": e.recording_id, "partner": e.partner,
                         "status": "tool_failure" if e.tool_failures else
                         ("findings" if e.exit_code(self.fail_on) else "valid"),
                         "error": "; ".join(f"{t.code}: {t.error}"
                                            for t in e.tool_failures) or None,
                         "counts": e.counts,
                         "top_rules": [r.code for r in e.rules[:5]],
                         # the full report, which only validation entries have
                         "report_file": getattr(e, "report_file", None)})
            if rows[-1]["report_file"]:  # its HTML page, next to it (dataset-report.html too)
                rows[-1]["report_html"] = Path(rows[-1]["report_file"]).with_suffix(".html").name
        return rows[:n]

    def _valid(self) -> int:
        return sum(1 for e in self.entries if e.exit_code(self.fail_on) == 0)

    def to_dict(self, top: int = 20) -> dict[str, Any]:
        return {
            "kind": self.kind, "dataset": self.specs, "tool_version": __version__,
            "fail_on": self.fail_on, "exit_code": int(self.exit_code),
            "recordings": self.recordings, "completed": len(self.entries),
            "failed": len(self.failed), "valid": self._valid(), "counts": self.counts,
            "by_rule": {k: v.model_dump(mode="json") for k, v in self.by_rule().items()},
            "by_partner": self.by_partner(), "worst": self.worst(top),
            "failures": [f.to_dict() for f in self.failed],
            "entries": [e.to_dict() for e in sorted(self.entries, key=lambda e: e.path)],
            "seconds": round(self.seconds, 3), "runner": self.runner,
        }

    def to_json(self, top: int = 20) -> str:
        return json.dumps(self.to_dict(top), indent=2, default=str)

    def to_pandas(self):  # -> pandas.DataFrame
        """One row per recording (completed or failed), sorted by path: ``path``, the facts
        (``recording_id``, ``partner``, ``method``, ``provenance``, ``site``, ``country``,
        ``road_type``), ``status`` (``valid``, ``findings``, ``tool_failure`` or ``failed``),
        ``exit_code``, the counts ``error``, ``warning``, ``info`` (nullable: none for a failed
        recording), ``top_rule`` (its most severe rule with findings) and ``failure`` (the
        error of a failed recording or of a crashed rule). Needs pandas
        (``pip install "aveas-format[pandas]"``)."""
        from aveas_format.errors import require

        pd = require("pandas", extra="pandas", what="DatasetReport.to_pandas")
        facts = [k for k in RecordingRef.model_fields if k != "path"]
        rows: list[dict[str, Any]] = []
        for e in self.entries:
            code = e.exit_code(self.fail_on)
            top = max((r for r in e.rules if r.count), default=None,
                      key=lambda r: (r.severity.rank, r.count))
            rows.append({"path": e.path, **{k: getattr(e, k) for k in facts},
                         "status": {0: "valid", 1: "findings"}.get(code, "tool_failure"),
                         "exit_code": code, **{s.value: e.counts.get(s.value, 0) for s in Severity},
                         "top_rule": top.code if top else None,
                         "failure": "; ".join(f"{t.code}: {t.error}" for t in e.tool_failures)
                         or None})
        for f in self.failed:
            rows.append({"path": f.path, **{k: getattr(f, k) for k in facts}, "status": "failed",
                         "exit_code": 3, **{s.value: None for s in Severity}, "top_rule": None,
                         "failure": f.error})
        rows.sort(key=lambda r: r["path"])
        dtypes = {"exit_code": "Int64", **{s.value: "Int64" for s in Severity}}
        columns = ["path", *facts, "status", "exit_code", *(s.value for s in Severity),
                   "top_rule", "failure"]
        return pd.DataFrame({c: pd.array([r[c] for r in rows], dtype=dtypes.get(c, "string"))
                             for c in columns})

    def __repr__(self) -> str:
        c, failed = self.counts, len(self.failed)
        return (f"<DatasetReport {self.kind}: {self.recordings} recordings, {self._valid()} valid"
                f"{f', {failed} failed' if failed else ''}; {c['error']} errors, "
                f"{c['warning']} warnings, {c['info']} info; exit code {int(self.exit_code)}>")

    def to_text(self) -> str:
        lines = []
        for e in sorted(self.entries, key=lambda e: e.path):
            c = e.counts
            status = {0: "ok", 1: "findings", 3: "tool-failure"}[e.exit_code(self.fail_on)]
            lines.append(f"{e.path}: {status} ({c.get('error', 0)} errors, "
                         f"{c.get('warning', 0)} warnings, {c.get('info', 0)} infos)")
        for f in sorted(self.failed, key=lambda f: f.path):
            lines.append(f"{f.path}: FAILED {f.error}")
        c = self.counts
        findings = sum(1 for e in self.entries if e.exit_code(self.fail_on) == 1)
        failed = len(self.failed) + sum(1 for e in self.entries if e.tool_failures)
        lines.append(f"{self.recordings} recordings: {self._valid()} valid, {findings} with "
                     f"findings, {failed} failed; {c['error']} errors, {c['warning']} warnings, "
                     f"{c['info']} infos in {self.seconds:.1f} s")
        return "\n".join(lines) + "\n"

    def to_html(self, top: int = 20) -> str:
        return render_dataset_html(self.to_dict(top))


def run_dataset(fn: Callable[[Any], RecordingEntry], items: Iterable[Any], *, kind: str,
                specs: list[str] | None = None, fail_on: str = "error", workers: int | None = 1,
                scheduler: str | None = None, progress: bool = False,
                on_result: Callable[[TaskResult], None] | None = None,
                name: Callable[[Any], str] | None = None) -> DatasetReport:
    """Map ``fn`` over items (recording paths, or tuples whose ``name(item)`` names the
    recording) and collect a :class:`DatasetReport` (``on_result`` is called with every result as
    it arrives, e.g. to print it)."""
    items = [str(i) for i in items] if name is None else list(items)
    label = name or str
    rep = DatasetReport(kind, specs or [label(i) for i in items], fail_on)
    rep.runner = {"workers": None if scheduler else (workers or os.cpu_count()),
                  "scheduler": scheduler}
    t0 = time.perf_counter()
    for r in run_tasks(fn, items, workers=workers, scheduler=scheduler, progress=progress,
                       description=kind):
        r.item = label(r.item)
        rep.add(r)
        if on_result is not None:
            on_result(r)
    rep.seconds = time.perf_counter() - t0
    return rep
