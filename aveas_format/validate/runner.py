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
from aveas_format.validate.context import Context
from aveas_format.validate.registry import Hit, Hits, Rule, select_rules
from aveas_format.validate.report import Finding, Location, Report, RuleResult, ToolFailure

#: Findings kept per rule (the count is always the true total).
DEFAULT_MAX_SAMPLE = 50
_LOCATION_FIELDS = set(Location.model_fields)


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
    if "row" in loc:
        loc["row"] = int(loc["row"])
    if "participant_id" in loc:
        loc["participant_id"] = int(loc["participant_id"])
    for k in ("time", "x", "y"):
        if k in loc and isinstance(loc[k], (int, float)):
            loc[k] = float(loc[k])
    ctx = {k: v for k, v in fields.items() if k not in _LOCATION_FIELDS}
    try:
        message = r.message.format_map(_SafeDict(fields))
    except (ValueError, TypeError, IndexError, KeyError):
        message = r.message
    return Finding(code=r.code, severity=r.severity, message=message,
                   location=Location(**loc), context=ctx)


def run_rule(r: Rule, ctx: Context, max_sample: int = DEFAULT_MAX_SAMPLE) -> RuleResult:
    """Run one rule; exceptions propagate to the caller (a tool failure)."""
    res = RuleResult(code=r.code, severity=r.severity, title=r.title)
    t0 = time.perf_counter()
    for item in r.fn(ctx):
        if isinstance(item, Hit):
            res.count += 1
            if len(res.sample) < max_sample:
                res.sample.append(_finding(r, item.fields))
        elif isinstance(item, Hits):
            if item.total == 0:
                continue
            res.count += item.total
            room = max_sample - len(res.sample)
            k = min(room, item.total)
            for i in range(k):
                fields = dict(item.const)
                fields.update({name: arr[i] for name, arr in item.arrays.items() if i < len(arr)})
                res.sample.append(_finding(r, fields))
        else:
            raise TypeError(f"rule {r.code} yielded {type(item).__name__}, expected Hit or Hits")
    res.truncated = res.count > len(res.sample)
    res.seconds = round(time.perf_counter() - t0, 6)
    return res


def validate(source: str | Path | Recording, *, select: list[str] | None = None,
             ignore: list[str] | None = None, config: Any = None,
             max_sample: int = DEFAULT_MAX_SAMPLE) -> Report:
    """Validate a recording (a path to a directory/ZIP, or an in-memory Recording).

    Raises RecordingIOError when the path is not a recording at all; every problem inside the
    recording becomes a finding. A rule that raises becomes a tool failure in ``report.failures``.
    """
    rules = select_rules(select, ignore)
    t0 = time.perf_counter()
    ctx = Context(source, config=config)
    report = Report(recording=ctx.name, tool_version=__version__)
    try:
        for r in rules:
            report.rules_run.append(r.code)
            try:
                with np.errstate(all="ignore"):  # NaN/inf in data are findings, not warnings
                    res = run_rule(r, ctx, max_sample)
            except Exception as e:  # noqa: BLE001 — a crashing rule is a tool failure, by design
                report.failures.append(ToolFailure(code=r.code, error=f"{type(e).__name__}: {e}",
                                                   traceback=traceback.format_exc()))
                continue
            if res.count:
                report.results.append(res)
        d = ctx.meta_dict
        report.format_version = d.get("format_version") if isinstance(d, dict) else None
    finally:
        ctx.close()
    report.results.sort(key=lambda r: (-r.severity.rank, r.code))
    report.seconds = round(time.perf_counter() - t0, 6)
    return report
