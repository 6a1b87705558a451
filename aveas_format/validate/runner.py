"""Run rules over a recording and build the report."""

from __future__ import annotations

import math
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format._version import __version__
from aveas_format.io.recording import Recording
from aveas_format.numeric import fmt_num
from aveas_format.validate.context import Context
from aveas_format.validate.registry import COLLECTORS, Hit, Hits, Rule, select_rules
from aveas_format.validate.report import Finding, Location, Report, RuleResult, ToolFailure

#: Findings kept per rule (the count is always the true total).
DEFAULT_MAX_SAMPLE = 50
_LOCATION_FIELDS = set(Location.model_fields)
_INT_FIELDS = ("row", "participant_id", "line", "message_index", "object_id", "lane_id")
_STR_FIELDS = ("frame", "uid", "json_path", "entity")


class _SafeDict(dict):
    def __missing__(self, key: str) -> str:
        return "?"


def _plain(v: Any) -> Any:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return str(v)
    return v


def _finding(r: Rule, fields: dict[str, Any]) -> Finding:
    fields = {k: _plain(v) for k, v in fields.items() if v is not None}
    loc = {k: v for k, v in fields.items() if k in _LOCATION_FIELDS}
    for k in _INT_FIELDS:
        if k in loc:
            loc[k] = int(loc[k])
    for k in _STR_FIELDS:
        if k in loc:
            loc[k] = str(loc[k])
    for k in ("time", "x", "y"):
        if k in loc and isinstance(loc[k], (int, float)):
            loc[k] = float(loc[k])
    ctx = {k: v for k, v in fields.items() if k not in _LOCATION_FIELDS and k != "count"}
    try:  # numbers in the message rounded for people; the typed fields keep every digit
        message = r.message.format_map(_SafeDict({k: fmt_num(v) if isinstance(v, float) else v
                                                  for k, v in fields.items()}))
    except (ValueError, TypeError, IndexError, KeyError):
        message = r.message
    return Finding(code=r.code, severity=r.severity, message=message,
                   location=Location(**loc), context=ctx, count=int(fields.get("count", 1)))


def _map_row(fields: dict[str, Any], ctx: Context | None) -> dict[str, Any]:
    """In a batch context, the batch row of a finding on the batch's table -> its file row."""
    if ctx is not None and ctx.file_rows and "row" in fields:
        rows = ctx.file_rows.get(fields.get("table"))
        if rows is not None:
            r = int(fields["row"])
            if 0 <= r < len(rows):
                fields = {**fields, "row": int(rows[r])}
    return fields


def run_rule(r: Rule, ctx: Context, max_sample: int = DEFAULT_MAX_SAMPLE,
             res: RuleResult | None = None) -> RuleResult:
    """Run one rule on one context, adding to ``res`` (a new result if None); exceptions
    propagate to the caller (a tool failure)."""
    if res is None:
        res = RuleResult(code=r.code, severity=r.severity, title=r.title)
    t0 = time.perf_counter()
    for item in r.fn(ctx):
        if isinstance(item, Hit):
            res.count += int(item.fields.get("count", 1))  # a source finding stands for many
            if len(res.sample) < max_sample:
                res.sample.append(_finding(r, _map_row(item.fields, ctx)))
        elif isinstance(item, Hits):
            if item.total == 0:
                continue
            res.count += item.total
            room = max_sample - len(res.sample)
            k = min(room, item.total)
            for i in range(k):
                fields = dict(item.const)
                fields.update({name: arr[i] for name, arr in item.arrays.items() if i < len(arr)})
                res.sample.append(_finding(r, _map_row(fields, ctx)))
        else:
            raise TypeError(f"rule {r.code} yielded {type(item).__name__}, expected Hit or Hits")
    res.truncated = res.count > len(res.sample)
    res.seconds = round(res.seconds + time.perf_counter() - t0, 6)
    return res


class _Run:
    """Results of one validation: rule results accumulated over passes, and tool failures."""

    def __init__(self, report: Report, max_sample: int) -> None:
        self.report = report
        self.max_sample = max_sample
        self.results: dict[str, RuleResult] = {}
        self.failed: set[str] = set()

    def rule(self, r: Rule, ctx: Context) -> None:
        if r.code in self.failed:
            return
        try:
            with np.errstate(all="ignore"):  # NaN/inf in data are findings, not warnings
                self.results[r.code] = run_rule(r, ctx, self.max_sample, self.results.get(r.code))
        except Exception as e:  # noqa: BLE001 — a crashing rule is a tool failure, by design
            self.fail(r.code, e)

    def fail(self, code: str, e: Exception) -> None:
        self.failed.add(code)
        self.results.pop(code, None)
        self.report.failures.append(ToolFailure(code=code, error=f"{type(e).__name__}: {e}",
                                                traceback=traceback.format_exc()))


def validate(source: str | Path | Recording | list[str | Path], *, select: list[str] | None = None,
             ignore: list[str] | None = None, config: Any = None,
             max_sample: int = DEFAULT_MAX_SAMPLE, source_findings: list[Any] | None = None,
             name: str | None = None, converter: str | None = None,
             map_source: str | Path | bytes | None = None, options: dict[str, Any] | None = None,
             crs: str | None = None) -> Report:
    """Validate a recording (a path to a directory/ZIP, or an in-memory Recording), or a submitted
    file of any importable format (a path to another file, or with ``converter`` a list of its
    input files): imported on the fly as ``aveas-format validate FILE`` imports it
    (:mod:`aveas_format.validate.submission`: the importer from the registry's patterns and
    sniffing, or ``converter``; ``map_source``, ``options``, ``crs`` as ``convert`` takes them),
    the import's findings about the file reported by the ``source.*`` rules.

    ``source_findings``: the :class:`~aveas_format.errors.SourceFinding` list an import collected
    (:func:`~aveas_format.errors.collect_source_findings`) when the recording was just imported from
    a submitted file; the ``source.*`` rules report them. ``name``: the report's ``recording``
    (default: the path, or the recording id of an in-memory one).

    Raises RecordingIOError when the path is not a recording at all; every problem inside the
    recording becomes a finding. A rule that raises becomes a tool failure in ``report.failures``.

    Tables above ``[streaming] above_rows`` rows are streamed: ``scope="rows"`` rules run on each
    batch, collectors gather what the ``recording`` rules need across participants, and the
    ``recording`` rules run once at the end (docs/validate.md, "Streaming").
    """
    if not isinstance(source, Recording) and source_findings is None:
        from aveas_format.validate.submission import imported, submitted_files

        files = submitted_files(list(source) if isinstance(source, (list, tuple)) else [source],
                                converter)
        if files:
            select_rules(select, ignore)  # a usage error before the import's work
            with imported(files, converter, map_source, options, crs) as (rec, found):
                return validate(rec, select=select, ignore=ignore, config=config,
                                max_sample=max_sample, source_findings=found,
                                name=name or " ".join(str(p) for p in files))
    rules = select_rules(select, ignore)
    t0 = time.perf_counter()
    ctx = Context(source, config=config)
    ctx.source_findings = list(source_findings or [])
    report = Report(recording=name or ctx.name, tool_version=__version__)
    run = _Run(report, max_sample)
    row_rules = [r for r in rules if r.scope == "rows"]
    rec_rules = [r for r in rules if r.scope == "recording"]
    needed = [COLLECTORS[k] for k in dict.fromkeys(k for r in rec_rules for k in r.needs)]
    partials: dict[str, list[Any]] = {c.key: [] for c in needed}
    try:
        report.rules_run = [r.code for r in rules]
        for pctx in ctx.passes():
            for name in pctx.file_rows:
                report.streamed[name] = report.streamed.get(name, 0) + 1
            for r in row_rules:
                run.rule(r, pctx)
            if "states" not in pctx.row_tables:
                continue
            for c in needed:
                if c.key in run.failed:
                    continue
                try:
                    with np.errstate(all="ignore"):
                        partials[c.key].append(c.collect(pctx))
                except Exception as e:  # noqa: BLE001 — a tool failure, like a crashing rule
                    run.fail(c.key, e)
        for c in needed:
            if c.key in run.failed:
                continue
            try:
                with np.errstate(all="ignore"):
                    ctx.collected[c.key] = c.merge([p for p in partials.pop(c.key) if p is not None])
            except Exception as e:  # noqa: BLE001
                run.fail(c.key, e)
        # rules reading collected data first, which is then released for the others
        for r in sorted(rec_rules, key=lambda r: not r.needs):
            if not r.needs and ctx.collected:
                ctx.collected.clear()
                ctx.cache.clear()
            run.rule(r, ctx)
        d = ctx.meta_dict
        report.format_version = d.get("format_version") if isinstance(d, dict) else None
    finally:
        ctx.close()
    report.results = [res for code in report.rules_run
                      if (res := run.results.get(code)) is not None and res.count]
    report.results.sort(key=lambda r: (-r.severity.rank, r.code))
    report.seconds = round(time.perf_counter() - t0, 6)
    return report
