"""``aveas-format validate REC``: check a recording against the format; ``validate FILE``: a
submitted file of any importable format (OpenLABEL, OSI, OpenSCENARIO...), imported on the fly.

A submission is imported and validated as :mod:`aveas_format.validate.submission` does it for
``aveas_format.validate(FILE)`` (the importer from ``--from`` or the registry's patterns and
sniffing; the import's findings about the file as the ``source.*`` rules' findings). Memory: an
importer that writes the recording itself (OpenLABEL) writes a large file's into a temporary
directory, its states in parts, and the recording is validated from there, streamed (1.7 GB for
9.2 M states); others hold the imported recording's columns (about 0.3 kB per state).
"""

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
    converter_name_option,
    converter_options,
    converter_workers,
    crs_option,
    discover_dataset,
    format_option,
    ignore_option,
    map_option,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    print_failure,
    recordings_argument,
    scheduler_option,
    select_option,
    set_verbose,
    single_recording,
    verbose_option,
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
    output_: str = typer.Option(None, "--output", "-o", metavar="PATH",
                                help="Write the report to FILE instead of "
                                "stdout; to a DIRECTORY (an existing one, or a path ending in /): "
                                "write report.json and report.html there in one run."),
    overwrite: bool = overwrite_option("Replace existing report files."),
    docs_url: str = typer.Option(None, "--docs-url", help="HTML: base URL of the aveas-format "
                                 "docs; each rule then links to its entry in rules.md there "
                                 "(without it the page stands alone)."),
    config: Path = typer.Option(None, "--config", help="TOML file of rule thresholds (see "
                                "`--print-config` for every key and its default)."),
    max_sample: int = typer.Option(50, "--max-sample", min=1, max=1000,
                                   help="Findings kept per rule (counts are always complete)."),
    report_schema: bool = typer.Option(False, "--report-schema", help="Print the JSON Schema of "
                                       "the JSON report and exit."),
    print_config: bool = typer.Option(False, "--print-config", help="Print the default "
                                      "thresholds as TOML and exit."),
    workers: int = workers_option(scope="Dataset, or a submission file read in blocks (OpenLABEL)"),
    scheduler: str = scheduler_option(scope="Dataset", help="address of a Dask scheduler "
                                      "(tcp://HOST:PORT) to run on instead of local processes "
                                      "(needs aveas-format[dask])."),
    reports_dir: Path = typer.Option(None, "--reports-dir", help="Dataset: write every "
                                     "recording's JSON report and the dataset report (JSON + "
                                     "HTML) into this directory."),
    top: int = typer.Option(20, "--top", min=1, help="Dataset: worst recordings listed."),
    source: str = converter_name_option("A submitted file (or files): the converter that "
                                        "imports it (see `convert --list`); default: by its "
                                        "extension."),
    map_file: Path = map_option("A submitted file: the OpenDRIVE map its data refers to."),
    crs: str = crs_option(),
    option: list[str] = option_pairs_option("A submitted file: converter"),
    options_file: Path = options_file_option("A submitted file: converter"),
    verbose: bool = verbose_option(),
) -> None:
    """Validate a recording, or a submitted file of any importable format (`validate
    submission.json`, `validate --from osi trace.osi --map map.xodr`): imported on the fly, its
    findings located in the file's own terms (rules source.*). Exit codes: 0 valid, 1 findings
    at/above --fail-on, 2 usage error, 3 unreadable input or tool failure."""
    from aveas_format.validate.config import ValidationConfig, config_toml
    from aveas_format.validate.report import report_json_schema

    set_verbose(verbose)
    if report_schema:
        _print_and_exit(json.dumps(report_json_schema(), indent=2))
    if print_config:
        _print_and_exit(config_toml())
    if not recordings:
        raise fail("Missing argument 'RECORDING'.", EXIT_USAGE)
    out_dir = _output_dir(output_)
    output = Path(output_) if output_ and out_dir is None else None
    if output is not None:  # before any work: never replaced without --overwrite
        check_output(output, overwrite)
    if reports_dir is not None:
        check_output_dir(reports_dir, overwrite)

    from aveas_format.errors import FormatError
    from aveas_format.validate import validate as run

    try:
        cfg = ValidationConfig.load(config)
    except FormatError as e:
        raise fail(str(e), EXIT_USAGE) from None
    only, skip = comma_list(select), comma_list(ignore)
    from aveas_format.validate.submission import imported, importer_of, submitted_files

    submission = submitted_files(recordings, source)
    recording = None if submission else single_recording(recordings)
    if recording is None and not submission:
        if out_dir is not None and reports_dir is None:  # -o DIR/ of a dataset: its reports dir
            reports_dir, output = out_dir, None
            if out_dir.is_dir():
                check_output([out_dir / "dataset-report.json", out_dir / "dataset-report.html"], overwrite)
        _validate_dataset(recordings, only, skip, cfg, max_sample, fail_on.value, fmt, output,
                          workers, scheduler, reports_dir, top)
    targets = ([out_dir / "report.json", out_dir / "report.html"] if out_dir is not None else
               [output] if output is not None else [])
    if out_dir is None or out_dir.is_dir():
        check_output(targets, overwrite)
    if submission:
        check_rules(only, skip)  # a usage error before the import's work
        from aveas_format.converters.registry import get_converter

        name = importer_of(submission, source)
        model = get_converter(name).options
        opts = converter_workers(converter_options(options_file, option, model), model, workers)
        with imported(submission, name, map_file, opts, crs) as (rec, found):
            report = run(rec, select=only, ignore=skip, config=cfg, max_sample=max_sample,
                         source_findings=found, name=" ".join(str(p) for p in submission))
            _finish(report, rec, out_dir, output, fmt, fail_on, docs_url)
    try:
        report = run(recording, select=only, ignore=skip, config=cfg, max_sample=max_sample)
    except ValueError as e:
        if "unknown rule or family" in str(e):
            raise fail(str(e), EXIT_USAGE) from None
        raise
    _finish(report, recording, out_dir, output, fmt, fail_on, docs_url)


def _finish(report, figures, out_dir: Path | None, output: Path | None, fmt, fail_on, docs_url) -> NoReturn:
    """The report written (``-o DIR/``: JSON and HTML; ``-o FILE``; else stdout) and the exit
    code (``figures``: the recording, or its path, for the HTML's figures)."""
    from aveas_format.validate.render import render_json, render_text

    if out_dir is not None:
        from aveas_format.plot.report_html import render_html
        from aveas_format.safeio import write_text_atomic

        out_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out_dir / "report.json", render_json(report))
        write_text_atomic(out_dir / "report.html", render_html(
            report, _open_for_figures(figures, report), docs_url=docs_url))
        err.print(f"{_summary_line(report, fail_on.value)}; wrote {out_dir / 'report.json'}, "
                  f"{out_dir / 'report.html'}", markup=False, highlight=False)
        raise typer.Exit(report.exit_code(fail_on.value))
    if fmt is Format.json:
        text = render_json(report)
    elif fmt is Format.html:
        from aveas_format.plot.report_html import render_html

        text = render_html(report, _open_for_figures(figures, report), docs_url=docs_url)
    else:
        text = render_text(report, fail_on=fail_on.value)
    if output:
        from aveas_format.safeio import write_text_atomic

        write_text_atomic(output, text)
        # the report went to a file: one line on stderr with its verdict and where it is
        err.print(f"{_summary_line(report, fail_on.value)}; wrote {output}", markup=False,
                  highlight=False)
    else:
        print(text, end="" if text.endswith("\n") else "\n")
    raise typer.Exit(report.exit_code(fail_on.value))


def _summary_line(report, fail_on: str) -> str:
    """The last line of the text report: the recording, the verdict at ``fail_on``, the counts."""
    from aveas_format.validate.render import render_text

    return render_text(report, fail_on=fail_on).rstrip().rsplit("\n", 1)[-1]




def _output_dir(typed: str | None) -> Path | None:
    """The directory ``-o`` names (an existing directory, or a path typed with a trailing
    separator: ``-o report/``), else None (a file, or stdout)."""
    import os

    if not typed:
        return None
    path = Path(typed)
    return path if path.is_dir() or typed.endswith(("/", os.sep)) else None


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


def _open_for_figures(path, report=None):
    """The recording for the report's figures (the columns they draw; of a large recording, a
    subset of its participants), or None when it cannot be read; an imported submission (a
    Recording in memory) as it is."""
    from aveas_format.plot.recording import open_for_figures

    if not isinstance(path, (str, Path)):
        return path
    try:
        return open_for_figures(path, report)
    except Exception:  # noqa: BLE001 — a broken recording still gets its report, without figures
        return None
