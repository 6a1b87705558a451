"""``aveas-format convert``: foreign formats -> recording (and ``--list``)."""

from __future__ import annotations

from pathlib import Path
import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, converter_options, err, fail, handle_errors, out


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
    each: bool = typer.Option(False, "--each", help="Many recordings: each INPUT (a file, or a "
                              "directory of files) becomes OUTPUT/NAME.aveas; OUTPUT is a directory."),
    group: str = typer.Option(None, "--group", help="With --each: group input files into "
                              "recordings by the first capture group of this regular expression on "
                              "their names, e.g. '^(\\d+)_' for levelX."),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="With --each: local worker "
                                "processes (0 = one per core)."),
    scheduler: str = typer.Option(None, "--scheduler", help="With --each: address of a Dask "
                                  "scheduler (tcp://HOST:PORT)."),
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
    raw = converter_options(options_file, option, conv.options)
    if each or group:
        _convert_many(source, [str(i) for i in inputs], map_file, raw, output, group, overwrite,
                      validate_, workers, scheduler)
        return
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


def _convert_many(source: str, inputs: list[str], map_file: Path | None, raw: dict, output: Path,
                  group: str | None, overwrite: bool, validate_: bool, workers: int,
                  scheduler: str | None) -> None:
    """One recording per input (or per --group), in parallel; a failing source is reported and
    the others complete. Exit 3 when any failed, 1 when any result has validation errors."""
    import json

    from aveas_format.dataset import convert_dataset

    if output.exists() and not output.is_dir():
        raise fail(f"{output}: with --each, --output is a directory", EXIT_USAGE)

    def stream(r) -> None:
        if not r.ok:
            err.print(f"failed {r.item}: {r.error}", markup=False, highlight=False)

    rep = convert_dataset(inputs, source=source, output_dir=output,
                          map_source=str(map_file) if map_file else None, options=raw,
                          group=group, overwrite=overwrite, validate=validate_,
                          workers=workers or None, scheduler=scheduler, progress=True,
                          on_result=stream)
    d = rep.to_dict()
    print(json.dumps({"recordings": d["recordings"], "completed": d["completed"],
                      "failed": d["failed"], "seconds": d["seconds"],
                      "results": [{k: e.get(k) for k in ("path", "output", "participants", "states",
                                                          "counts")} for e in d["entries"]],
                      "failures": [{"path": f["path"], "error": f["error"]}
                                   for f in d["failures"]]}, indent=2))
    err.print(f"converted {d['completed']} of {d['recordings']} -> {output}"
              + (f", {d['failed']} failed" if d["failed"] else ""))
    raise typer.Exit(rep.exit_code())
