"""``aveas-format convert``: foreign formats -> recording (and ``--list``)."""

from __future__ import annotations

from pathlib import Path
import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out
from aveas_format.cli.options import (
    converter_options,
    crs_option,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    print_failure,
    refuse_overwrite,
    run_summary,
    scheduler_option,
    validate_option,
    validate_written,
    workers_option,
)


@app.command()
@handle_errors
def convert(
    inputs: list[Path] = typer.Argument(None, help="Input files of the source format."),
    source: str = typer.Option(None, "--from", "-f", help="Converter name (see --list)."),
    map_file: Path = typer.Option(None, "--map", "-m", help="The OpenDRIVE map the data refers to."),
    output: Path = typer.Option(None, "--output", "-o", help="Output recording (NAME.aveas or "
                                "NAME.aveas.zip)."),
    crs: str = crs_option(),
    option: list[str] = option_pairs_option("Converter"),
    options_file: Path = options_file_option("Converter"),
    overwrite: bool = overwrite_option(),
    list_: bool = typer.Option(False, "--list", help="List the converters and exit."),
    each: bool = typer.Option(False, "--each", help="Many recordings: each INPUT (a file, or a "
                              "directory of files) becomes OUTPUT/NAME.aveas; OUTPUT is a directory."),
    group: str = typer.Option(None, "--group", help="With --each: group input files into "
                              "recordings by the first capture group of this regular expression on "
                              "their names, e.g. '^(\\d+)_' for levelX."),
    workers: int = workers_option(scope="With --each",
                                  help="local worker processes (0 = one per core)."),
    scheduler: str = scheduler_option(scope="With --each",
                                      help="address of a Dask scheduler (tcp://HOST:PORT)."),
    validate_: bool = validate_option(),
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
    raw = converter_options(options_file, option, conv.options)
    if crs:
        raw["crs"] = crs
    if each or group:
        _convert_many(source, [str(i) for i in inputs], map_file, raw, output, group, overwrite,
                      validate_, workers, scheduler)
        return
    refuse_overwrite(output, overwrite)
    from aveas_format.converters.registry import convert as run

    rec = run(source, inputs, map_source=map_file, options=raw)
    path = rec.write(output, overwrite=overwrite)
    n = rec.states.num_rows
    on_map = (n - rec.states.column("road_id").null_count) / n if n else 0.0
    err.print(f"wrote {path}: {rec.participants.num_rows} participants, {n:,} states, "
              f"{on_map:.1%} on the map")
    if validate_:
        validate_written(path)  # map.mostly_off_road among the rules
    else:
        _off_map_note(path)


def _off_map_note(path: Path) -> None:
    """Without --validate, still say when the recording is mostly off its map (wrong map, CRS,
    offset, axes or unit): the one finding a conversion must not keep quiet about."""
    import aveas_format

    for f in aveas_format.validate(path, select=["map.mostly_off_road"]).findings():
        err.print(f"warning: {f.message}", markup=False, highlight=False)


def _convert_many(source: str, inputs: list[str], map_file: Path | None, raw: dict, output: Path,
                  group: str | None, overwrite: bool, validate_: bool, workers: int,
                  scheduler: str | None) -> None:
    """One recording per input (or per --group), in parallel; a failing source is reported and
    the others complete. Exit 3 when any failed, 1 when any result has validation errors."""
    import json

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
