"""``aveas-format convert``: foreign formats -> recording (and ``--list``)."""

from __future__ import annotations

import json
import typing
from pathlib import Path
from typing import Any

import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out


def parse_option_pairs(pairs: list[str], model: type) -> dict[str, Any]:
    """``["net_file=a.net.xml", "vtypes=a.rou.xml,b.rou.xml", "geo=true"]`` -> dict.

    Values are read as JSON where they parse (numbers, booleans, lists), else as strings; a
    comma-separated string becomes a list for list-typed options.
    """
    out_: dict[str, Any] = {}
    fields = getattr(model, "model_fields", {})
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--option {pair!r}: expected KEY=VALUE")
        key, raw = pair.split("=", 1)
        key = key.strip().replace("-", "_")
        try:
            value: Any = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        ann = fields[key].annotation if key in fields else None
        if typing.get_origin(ann) in (list, tuple) and isinstance(value, str):
            value = [v for v in value.split(",") if v]
        out_[key] = value
    return out_


@app.command()
@handle_errors
def convert(
    inputs: list[Path] = typer.Argument(None, help="Input files of the source format."),
    source: str = typer.Option(None, "--from", "-f", help="Converter name (see --list)."),
    map_file: Path = typer.Option(None, "--map", "-m", help="The OpenDRIVE map the data refers to."),
    output: Path = typer.Option(None, "--output", "-o", help="Output recording (NAME.aveas or "
                                "NAME.aveas.zip)."),
    option: list[str] = typer.Option(None, "--option", "-O", help="Converter option KEY=VALUE "
                                     "(repeatable; see docs/converters.md)."),
    options_file: Path = typer.Option(None, "--options", help="Converter options as a JSON file."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing output."),
    list_: bool = typer.Option(False, "--list", help="List the converters and exit."),
    validate_: bool = typer.Option(True, "--validate/--no-validate", help="Validate the result "
                                   "and report errors (exit 1 when it has any)."),
) -> None:
    """Convert source data into a recording: `aveas-format convert --from sumo-fcd fcd.xml --map
    net.xodr -o run.aveas`."""
    from aveas_format.converters.registry import get_converter, load_converters

    if list_:
        t = Table(show_edge=False)
        for col in ("name", "direction", "method", "inputs", "description"):
            t.add_column(col)
        for c in sorted(load_converters().values(), key=lambda c: (c.direction, c.name)):
            t.add_row(c.name, c.direction, c.method or "", " ".join(c.patterns), c.description)
        out.print(t)
        return
    if not source or not inputs or not output:
        raise fail("--from NAME, INPUT... and --output are required (or --list)", EXIT_USAGE)
    conv = get_converter(source)
    raw: dict[str, Any] = {}
    if options_file:
        try:
            raw.update(json.loads(options_file.read_text()))
        except (OSError, json.JSONDecodeError) as e:
            raise fail(f"{options_file}: cannot read options: {e}", EXIT_USAGE) from None
    try:
        raw.update(parse_option_pairs(option or [], conv.options))
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None
    if output.exists() and not overwrite:
        raise fail(f"{output}: exists; pass --overwrite to replace it", EXIT_USAGE)
    from aveas_format.converters.registry import convert as run

    rec = run(source, inputs, map_source=map_file, options=raw)
    path = rec.write(output, overwrite=overwrite)
    err.print(f"wrote {path}: {rec.participants.num_rows} participants, "
              f"{rec.states.num_rows:,} states")
    if validate_:
        import aveas_format
        from aveas_format.validate.render import render_text

        report = aveas_format.validate(path)
        if report.counts["error"]:
            out.print(render_text(report), end="")
            raise typer.Exit(1)
        err.print(f"valid: {report.counts['warning']} warnings, {report.counts['info']} info")
