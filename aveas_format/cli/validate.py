"""``aveas-format validate REC``: check a recording against the format."""

from __future__ import annotations

from enum import Enum
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, fail, handle_errors


class FailOn(str, Enum):
    error = "error"
    warning = "warning"
    never = "never"


class Format(str, Enum):
    text = "text"
    json = "json"


@app.command()
@handle_errors
def validate(
    recording: Path = typer.Argument(..., help="A recording: NAME.aveas directory or NAME.aveas.zip."),
    select: list[str] = typer.Option(None, "--select", help="Run only these rules (codes or "
                                     "families, repeatable or comma-separated)."),
    ignore: list[str] = typer.Option(None, "--ignore", help="Skip these rules (codes or families)."),
    fail_on: FailOn = typer.Option(FailOn.error, "--fail-on", help="Exit 1 when a finding at or "
                                   "above this severity exists."),
    fmt: Format = typer.Option(Format.text, "--format", help="Report format."),
    output: Path = typer.Option(None, "--output", "-o", help="Write the report to FILE instead of "
                                "stdout."),
    max_sample: int = typer.Option(50, "--max-sample", min=1, max=1000,
                                   help="Findings kept per rule (counts are always complete)."),
) -> None:
    """Validate a recording. Exit codes: 0 valid, 1 findings at/above --fail-on, 2 usage error,
    3 unreadable input or tool failure."""
    from aveas_format.validate import validate as run
    from aveas_format.validate.render import render_json, render_text

    def split(v: list[str] | None) -> list[str] | None:
        return [p.strip() for item in v for p in item.split(",") if p.strip()] if v else None

    try:
        report = run(recording, select=split(select), ignore=split(ignore), max_sample=max_sample)
    except ValueError as e:
        if "unknown rule or family" in str(e):
            raise fail(str(e), EXIT_USAGE) from None
        raise
    text = render_json(report) if fmt is Format.json else render_text(report)
    if output:
        from aveas_format.io.atomic import write_text_atomic

        write_text_atomic(output, text)
    else:
        print(text, end="" if text.endswith("\n") else "\n")
    raise typer.Exit(report.exit_code(fail_on.value))
