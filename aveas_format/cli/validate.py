"""``aveas-format validate REC``: check a recording against the format."""

from __future__ import annotations

import functools
import json
from enum import Enum
from pathlib import Path
from typing import NoReturn

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors
from aveas_format.cli.options import (
    check_output,
    check_output_dir,
    check_rules,
    comma_list,
    discover_dataset,
    format_option,
    ignore_option,
    overwrite_option,
    print_failure,
    recordings_argument,
    scheduler_option,
    select_option,
    single_recording,
    workers_option,
)


class FailOn(str, Enum):
    error = "error"
    warning = "warning"
    never = "never"


class Format(str, Enum):
    text = "text"
    json = "json"
    html = "html"


def _print_and_exit(text: str) -> None:
    print(text, end="" if text.endswith("\n") else "\n")
    raise typer.Exit(0)


@app.command()
@handle_errors
def validate(
    recordings: list[str] = recordings_argument(None, urls="file:// / s3:// URLs"),
    select: list[str] = select_option(),
    ignore: list[str] = ignore_option(),
    fail_on: FailOn = typer.Option(FailOn.error, "--fail-on", help="Exit 1 when a finding at or "
                                   "above this severity exists."),
    fmt: Format = format_option(Format.text, help="Report format: text (greppable lines + "
                                "summary), json, or html (self-contained, with figures)."),
    output: Path = typer.Option(None, "--output", "-o", help="Write the report to FILE instead of "
                                "stdout."),
    overwrite: bool = overwrite_option(help="Replace an existing --output (or the files of "
                                       "--reports-dir)."),
    config: Path = typer.Option(None, "--config", help="TOML file of rule thresholds (see "
                                "`--print-config` for every key and its default)."),
    max_sample: int = typer.Option(50, "--max-sample", min=1, max=1000,
                                   help="Findings kept per rule (counts are always complete)."),
    report_schema: bool = typer.Option(False, "--report-schema", help="Print the JSON Schema of "
                                       "the JSON report and exit."),
    print_config: bool = typer.Option(False, "--print-config", help="Print the default "
                                      "thresholds as TOML and exit."),
    workers: int = workers_option(scope="Dataset"),
    scheduler: str = scheduler_option(scope="Dataset", help="address of a Dask scheduler "
                                      "(tcp://HOST:PORT) to run on instead of local processes "
                                      "(needs aveas-format[dask])."),
    reports_dir: Path = typer.Option(None, "--reports-dir", help="Dataset: write every "
                                     "recording's JSON report and the dataset report (JSON + "
                                     "HTML) into this directory."),
    top: int = typer.Option(20, "--top", min=1, help="Dataset: worst recordings listed."),
) -> None:
    """Validate a recording. Exit codes: 0 valid, 1 findings at/above --fail-on, 2 usage error,
    3 unreadable input or tool failure."""
    from aveas_format.validate.config import ValidationConfig, config_toml
    from aveas_format.validate.report import report_json_schema

    if report_schema:
        _print_and_exit(json.dumps(report_json_schema(), indent=2))
    if print_config:
        _print_and_exit(config_toml())
    if not recordings:
        raise fail("Missing argument 'RECORDING'.", EXIT_USAGE)
    if output is not None:
        check_output(output, overwrite)
    if reports_dir is not None:
        check_output_dir(reports_dir, overwrite)
    if fmt is Format.html:
        from aveas_format.errors import require

        require("matplotlib", extra="plot", what="--format html")

    from aveas_format.errors import FormatError
    from aveas_format.validate import validate as run
    from aveas_format.validate.render import render_json, render_text

    try:
        cfg = ValidationConfig.load(config)
    except FormatError as e:
        raise fail(str(e), EXIT_USAGE) from None
    only, skip = comma_list(select), comma_list(ignore)
    recording = single_recording(recordings)
    if recording is None:
        _validate_dataset(recordings, only, skip, cfg, max_sample, fail_on.value, fmt, output,
                          workers, scheduler, reports_dir, top)
    try:
        report = run(recording, select=only, ignore=skip, config=cfg, max_sample=max_sample)
    except ValueError as e:
        if "unknown rule or family" in str(e):
            raise fail(str(e), EXIT_USAGE) from None
        raise
    if fmt is Format.json:
        text = render_json(report)
    elif fmt is Format.html:
        from aveas_format.plot.report_html import render_html

        text = render_html(report, _open_for_figures(recording, report))
    else:
        text = render_text(report)
    if output:
        from aveas_format.safeio import write_text_atomic

        write_text_atomic(output, text)
    else:
        print(text, end="" if text.endswith("\n") else "\n")
    raise typer.Exit(report.exit_code(fail_on.value))


def _validate_dataset(specs: list[str], select: list[str] | None, ignore: list[str] | None,
                      cfg, max_sample: int, fail_on: str, fmt: Format, output: Path | None,
                      workers: int, scheduler: str | None, reports_dir: Path | None,
                      top: int) -> NoReturn:
    """Validate every recording of a dataset, one task each; exit with the worst code."""
    from aveas_format.dataset import validate_dataset
    from aveas_format.safeio import write_text_atomic

    check_rules(select, ignore)
    paths = discover_dataset(specs, "validating", workers, scheduler)
    rep = validate_dataset(paths, select=select, ignore=ignore, config=cfg, max_sample=max_sample,
                           reports_dir=reports_dir, fail_on=fail_on, workers=workers or None,
                           scheduler=scheduler, progress=True, specs=list(specs),
                           on_result=functools.partial(print_failure, red=True))
    if reports_dir:
        write_text_atomic(reports_dir / "dataset-report.json", rep.to_json(top))
        write_text_atomic(reports_dir / "dataset-report.html", rep.to_html(top))
    text = (rep.to_json(top) if fmt is Format.json else rep.to_html(top) if fmt is Format.html
            else rep.to_text())
    if output:
        write_text_atomic(output, text)
        err.print(rep.to_text().rstrip().rsplit("\n", 1)[-1])
    else:
        print(text, end="" if text.endswith("\n") else "\n")
    raise typer.Exit(rep.exit_code())


def _open_for_figures(path: Path, report=None):
    """The recording for the report's figures (the columns they draw; of a large recording, a
    subset of its participants), or None when it cannot be read."""
    from aveas_format.plot.recording import open_for_figures

    try:
        return open_for_figures(path, report)
    except Exception:  # noqa: BLE001 — a broken recording still gets its report, without figures
        return None
