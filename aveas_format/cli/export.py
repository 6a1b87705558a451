"""``aveas-format export``: recording -> foreign formats (OpenLABEL, OpenSCENARIO, MCAP)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out
from aveas_format.cli.options import (
    converter_options,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    refuse_overwrite,
)


@app.command()
@handle_errors
def export(
    recording: Path = typer.Argument(None, help="The recording (NAME.aveas or NAME.aveas.zip)."),
    target: str = typer.Option(None, "--to", "-t", help="Exporter name: openlabel, openscenario, "
                               "mcap, osi (see --list)."),
    output: Path = typer.Option(None, "--output", "-o", help="Output file (companion files such "
                                "as the map are written next to it; --overwrite covers them too)."),
    option: list[str] = option_pairs_option("Exporter"),
    options_file: Path = options_file_option("Exporter"),
    overwrite: bool = overwrite_option(),
    list_: bool = typer.Option(False, "--list", help="List the exporters and exit."),
) -> None:
    """Export a recording to a foreign format: `aveas-format export --to openlabel run.aveas -o
    run.json` (also `--to openscenario` -> .xosc, `--to mcap` -> .mcap for Foxglove, `--to osi` ->
    an ASAM OSI GroundTruth trace, .osi or .mcap)."""
    from aveas_format.converters.registry import get_converter, load_converters

    if list_:
        t = Table(show_edge=False)
        for col in ("name", "description"):
            t.add_column(col)
        for c in sorted(load_converters().values(), key=lambda c: c.name):
            if c.direction == "export":
                t.add_row(c.name, c.description)
        out.print(t)
        return
    if not target or not recording or not output:
        raise fail("--to NAME, RECORDING and --output are required (or --list)", EXIT_USAGE)
    conv = get_converter(target, "export")
    raw = converter_options(options_file, option, conv.options)
    refuse_overwrite(output, overwrite)
    from aveas_format.converters.common import companion_map_path

    companion = companion_map_path(output, conv.parse_options(raw))
    if companion is not None:  # companion files are outputs too
        refuse_overwrite(companion, overwrite)
    if output.parent and not output.parent.exists():
        raise fail(f"{output.parent}: no such directory", EXIT_USAGE)
    import aveas_format

    rec = aveas_format.open(recording)
    paths = conv(rec, output, options=raw)
    for p in paths:
        err.print(f"wrote {p}")
