"""Validating a dataset: one validator run per recording, summarised as a :class:`ValidationEntry`.

The full report of each recording can be written by the worker that made it (``reports_dir``), so
only the compact entry travels back and a dataset of thousands never sits in one process.
"""

from __future__ import annotations

import functools
import hashlib
import re
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from aveas_format.dataset.discovery import local_copy
from aveas_format.dataset.report import (
    DatasetReport,
    RecordingEntry,
    RuleCount,
    ToolFailureSummary,
    read_facts,
    run_dataset,
)
from aveas_format.parallel import TaskResult


class ValidationEntry(RecordingEntry):
    """One validated recording: its findings (:class:`RecordingEntry`), the format version it
    declares, and where its full report was written (``reports_dir``), if anywhere."""

    format_version: str | None = None
    seconds: float = 0.0
    report_file: str | None = None


def _report_name(path: str) -> str:
    """A file name for a recording's report, unique over the dataset."""
    base = re.sub(r"(\.aveas)?(\.zip)?/?$", "", path.rstrip("/")).rsplit("/", 1)[-1] or "recording"
    base = re.sub(r"[^A-Za-z0-9._-]", "_", base)
    return f"{base}-{hashlib.sha1(path.encode()).hexdigest()[:8]}"


def _report_page(path: str, report: Any) -> str:
    """The recording's HTML report, with the summary of the recording but without figures: in a
    dataset's reports directory, drawing them would cost more than the validation."""
    from aveas_format.io.reader import open_recording
    from aveas_format.plot.report_html import render_html

    try:
        rec = open_recording(path, tables=["participants"], verify=False)
    except Exception:  # noqa: BLE001 — the report says the recording could not be read
        rec = None
    return render_html(report, rec, figures={},
                       no_figures="not drawn in a dataset's reports (aveas-format validate "
                                  "RECORDING -o DIR/ draws them)")


def validate_recording(path: str, *, select: list[str] | None = None,
                       ignore: list[str] | None = None, config: Any = None, max_sample: int = 50,
                       reports_dir: str | None = None) -> ValidationEntry:
    """Validate one recording (a task): a compact, picklable summary; the full report goes to
    ``reports_dir/NAME-HASH.json`` and ``.html`` (without figures) when given."""
    from aveas_format.validate.runner import validate

    t0 = time.perf_counter()
    with local_copy(path) as local:
        facts = read_facts(local)
        report = validate(local, select=select, ignore=ignore, config=config,
                          max_sample=max_sample)
        page = _report_page(local, report) if reports_dir else None
    report_file = None
    if reports_dir:
        from aveas_format.safeio import write_text_atomic

        report_file = str(Path(reports_dir) / f"{_report_name(path)}.json")
        write_text_atomic(report_file, report.to_json())
        write_text_atomic(str(Path(report_file).with_suffix(".html")), page)
    return ValidationEntry(
        path=path, **facts,
        counts=report.counts,
        rules=[RuleCount.of(r) for r in report.results],
        tool_failures=[ToolFailureSummary(code=f.code, error=f.error) for f in report.failures],
        format_version=report.format_version,
        seconds=round(time.perf_counter() - t0, 4),
        report_file=report_file,
    )


def validate_dataset(paths: Iterable[str | Path], *, select: list[str] | None = None,
                     ignore: list[str] | None = None, config: Any = None, max_sample: int = 50,
                     reports_dir: str | Path | None = None, fail_on: str = "error",
                     workers: int | None = 1, scheduler: str | None = None,
                     progress: bool = False, specs: list[str] | None = None,
                     on_result: Callable[[TaskResult], None] | None = None,
                     task: Callable[[str], ValidationEntry] | None = None) -> DatasetReport:
    """Validate every recording; one task per recording (``task`` replaces the default one, e.g.
    a wrapper; it must return what :func:`validate_recording` returns)."""
    if reports_dir is not None:
        Path(reports_dir).mkdir(parents=True, exist_ok=True)
    fn = task or functools.partial(validate_recording, select=select, ignore=ignore,
                                   config=config, max_sample=max_sample,
                                   reports_dir=str(reports_dir) if reports_dir else None)
    return run_dataset(fn, [str(p) for p in paths], kind="validate", specs=specs,
                       fail_on=fail_on, workers=workers, scheduler=scheduler, progress=progress,
                       on_result=on_result)
