"""``aveas-format convert``: foreign formats -> recording (and ``--list``)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, print_table
from aveas_format.cli.options import (
    OutputFormat,
    check_output,
    converter_name_option,
    converter_options,
    converter_workers,
    crs_option,
    format_option,
    map_option,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    print_failure,
    run_summary,
    scheduler_option,
    set_verbose,
    validate_option,
    validate_written,
    verbose_option,
    workers_option,
)


def list_converters(direction: str | None, fmt: OutputFormat) -> None:
    """``convert --list`` / ``export --list``: the converters of a direction (None: both), as a
    table (plain text when not a terminal) or as JSON (``--format json``)."""
    from aveas_format.converters.registry import load_converters

    convs = sorted((c for c in load_converters().values() if direction in (None, c.direction)),
                   key=lambda c: (c.direction, c.name))
    rows = [{"name": c.name, "direction": c.direction, "method": c.method,
             "inputs": list(c.patterns), "description": c.description, "extra": c.extra,
             "available": c.available} for c in convs]
    if fmt is OutputFormat.json:
        print(json.dumps(rows, indent=2))
        return
    cols = ("name", "direction", "method", "inputs", "needs", "description")
    print_table([(r["name"], r["direction"], r["method"] or "", " ".join(r["inputs"]),
                  (f"[{r['extra']}]" + ("" if r["available"] else " (not installed)"))
                  if r["extra"] else "", r["description"]) for r in rows],
                cols if direction is None else [c for c in cols if c != "direction"])


@app.command()
@handle_errors
def convert(
    inputs: list[Path] = typer.Argument(None, help="Input files of the source format."),
    source: str = converter_name_option(),
    map_file: Path = map_option(),
    output: Path = typer.Option(None, "--output", "-o", help="Output recording (NAME.aveas or "
                                "NAME.aveas.zip)."),
    crs: str = crs_option(),
    option: list[str] = option_pairs_option("Converter"),
    options_file: Path = options_file_option("Converter"),
    overwrite: bool = overwrite_option(),
    list_: bool = typer.Option(False, "--list", help="List the converters and exit."),
    fmt: OutputFormat = format_option(help="With --list: text (a table) or json."),
    each: bool = typer.Option(False, "--each", help="Many recordings: each INPUT (a file, or a "
                              "directory of files) becomes OUTPUT/NAME.aveas; OUTPUT is a directory."),
    group: str = typer.Option(None, "--group", help="With --each: group input files into "
                              "recordings by the first capture group of this regular expression on "
                              "their names, e.g. '^(\\d+)_' for levelX."),
    workers: int = workers_option(scope="With --each; for one input, of a converter that reads it in "
                                        "blocks (openlabel)"),
    scheduler: str = scheduler_option(scope="With --each",
                                      help="address of a Dask scheduler (tcp://HOST:PORT)."),
    validate_: bool = validate_option(),
    verbose: bool = verbose_option(),
) -> None:
    """Convert source data into a recording: `aveas-format convert --from sumo-fcd fcd.xml --map
    net.xodr -o run.aveas`."""
    from aveas_format.converters.registry import get_converter

    set_verbose(verbose)
    if list_:
        list_converters(None, fmt)
        return
    if not source or not inputs or not output:
        raise fail("--from NAME, INPUT... and --output are required (or --list)", EXIT_USAGE)
    conv = get_converter(source)
    raw = converter_options(options_file, option, conv.options)
    if crs:
        raw["crs"] = crs
    conv.parse_options(raw)  # usage errors (an unknown option, no map) first
    conv.check_map(map_file)
    if each or group:
        _convert_many(source, [str(i) for i in inputs], map_file, raw, output, group, overwrite,
                      validate_, workers, scheduler)
        return
    check_output(output, overwrite)
    from aveas_format.converters.registry import convert_to

    rec, n, on_road = convert_to(source, inputs, output, map_source=map_file, overwrite=overwrite,
                                 options=converter_workers(raw, conv.options, workers))
    path = rec.path
    on_map = on_road / n if n else 0.0
    err.print(f"wrote {path}: {rec.participants.num_rows} participants, {n:,} states, "
              f"{on_map:.1%} on the map")
    if validate_:  # (a recording mostly off its map: the import has warned, and
        validate_written(path)  # map.mostly_off_road is among the rules)


def _convert_many(source: str, inputs: list[str], map_file: Path | None, raw: dict, output: Path,
                  group: str | None, overwrite: bool, validate_: bool, workers: int,
                  scheduler: str | None) -> None:
    """One recording per input (or per --group), in parallel; a failing source is reported and
    the others complete. Exit 3 when any failed, 1 when any result has validation errors."""
    from aveas_format.dataset import convert_dataset

    if output.exists() and not output.is_dir():
        raise fail(f"{output}: with --each, --output is a directory", EXIT_USAGE)
    rep = convert_dataset(inputs, source=source, output_dir=output,
                          map_source=str(map_file) if map_file else None, options=raw,
                          group=group, overwrite=overwrite, validate=validate_,
                          workers=workers or None, scheduler=scheduler, progress=True,
                          on_result=print_failure)
    d = rep.to_dict()
    print(json.dumps(run_summary(d, ("path", "output", "participants", "states", "counts")),
                     indent=2))
    err.print(f"converted {d['completed']} of {d['recordings']} -> {output}"
              + (f", {d['failed']} failed" if d["failed"] else ""))
    raise typer.Exit(rep.exit_code())
