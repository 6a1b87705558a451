"""``aveas-format export``: recording -> foreign formats (OpenLABEL, OpenSCENARIO, MCAP, OSI)."""

from __future__ import annotations

from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors
from aveas_format.cli.convert import list_converters
from aveas_format.cli.options import (
    OutputFormat,
    check_output,
    converter_options,
    converter_workers,
    format_option,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    workers_option,
)


@app.command()
@handle_errors
def export(
    recording: Path = typer.Argument(None, help="The recording (NAME.aveas or NAME.aveas.zip)."),
    target: str = typer.Option(None, "--to", "-t", help="Exporter name: openlabel, openscenario, "
                               "mcap, osi (see --list)."),
    output: Path = typer.Option(None, "--output", "-o", help="Output file (companion files such "
                                "as the map are written next to it; they are outputs too)."),
    option: list[str] = option_pairs_option("Exporter"),
    options_file: Path = options_file_option("Exporter"),
    overwrite: bool = overwrite_option(help="Replace an existing output or companion file."),
    workers: int = workers_option(scope="Of an exporter that writes one output in parallel (openlabel)"),
    list_: bool = typer.Option(False, "--list", help="List the exporters and exit."),
    fmt: OutputFormat = format_option(help="With --list: text (a table) or json."),
) -> None:
    """Export a recording to a foreign format: `aveas-format export --to openlabel run.aveas -o
    run.json` (also `--to openscenario` -> .xosc, `--to mcap` -> .mcap for Foxglove, `--to osi` ->
    an ASAM OSI GroundTruth trace, .osi or .mcap)."""
    from aveas_format.converters.registry import get_converter

    if list_:
        list_converters("export", fmt)
        return
    if not target or not recording or not output:
        raise fail("--to NAME, RECORDING and --output are required (or --list)", EXIT_USAGE)
    conv = get_converter(target, "export")
    raw = converter_workers(converter_options(options_file, option, conv.options), conv.options, workers)
    import aveas_format

    outputs = conv.outputs(output, raw)
    same: set[Path] = set()
    maps = [p for p in outputs[1:] if p.suffix.lower() == ".xodr" and p.exists() and not overwrite]
    if maps:  # another export of this recording wrote the same map next to it: no conflict
        from aveas_format.converters.common.companion import is_same_companion

        head = aveas_format.open(recording, states=False)
        same = {p for p in maps if is_same_companion(head, p)}
        outputs = [p for p in outputs if p not in same]
    check_output(outputs, overwrite)  # the output and its companion files
    conv.require()  # a missing optional dependency before reading the recording

    # (an exporter that streams the states reads them from the file: bounded memory)
    rec = aveas_format.open(recording, states=not conv.streams_states)
    for p in conv(rec, output, options=raw):
        err.print(f"kept {p} (the same map, written by another export)" if p in same else f"wrote {p}")
