"""``aveas-format catalog DATASET -o catalog.parquet``: one row per recording, to search an archive
with DuckDB, Polars or pyarrow."""

from __future__ import annotations

from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors


@app.command()
@handle_errors
def catalog(
    dataset: list[str] = typer.Argument(..., metavar="DATASET...", help="Recordings: a "
                                        "directory of recordings, paths, globs or URLs."),
    output: Path = typer.Option(..., "--output", "-o", help="The catalog file: .parquet "
                                "(default), .csv or .jsonl."),
    validate: bool = typer.Option(True, "--validate/--no-validate", help="Run the validator "
                                  "for the validity columns (errors, warnings, valid)."),
    select: list[str] = typer.Option(None, "--select", help="Validate only these rules."),
    ignore: list[str] = typer.Option(None, "--ignore", help="Skip these rules."),
    workers: int = typer.Option(0, "--workers", "-j", min=0, help="Local worker processes "
                                "(0 = one per core, 1 = in this process)."),
    scheduler: str = typer.Option(None, "--scheduler", help="Address of a Dask scheduler "
                                  "(tcp://HOST:PORT) (needs aveas-format[dask])."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace OUTPUT if it exists."),
) -> None:
    """Catalog a dataset: one row per recording (id, partner, method, provenance, site, start
    time, duration, participants per class, rate, coverage area, validity, criticality) from
    recording.json and small tables only. Exit 3 when a recording could not be read (it still
    gets a row, with `read_error`)."""
    from aveas_format.dataset import catalog as build
    from aveas_format.dataset import discover, write_catalog

    if output.exists() and not overwrite:
        raise fail(f"{output}: exists; pass --overwrite to replace it", EXIT_USAGE)

    def split(v: list[str] | None) -> list[str] | None:
        return [p.strip() for item in v for p in item.split(",") if p.strip()] if v else None

    if validate:
        from aveas_format.validate.registry import select_rules

        try:
            select_rules(split(select), split(ignore))
        except ValueError as e:
            raise fail(str(e), EXIT_USAGE) from None
    paths = discover(dataset)
    err.print(f"cataloguing {len(paths)} recordings "
              + (f"on {scheduler}" if scheduler else f"with {workers or 'all'} worker(s)"))

    def stream(r) -> None:
        if not r.ok:
            err.print(f"failed {r.item}: {r.error}", markup=False, highlight=False)

    table = build(paths, validate=validate, workers=workers or None, scheduler=scheduler,
                  progress=True, select=split(select), ignore=split(ignore), on_result=stream)
    write_catalog(table, output)
    failed = table.num_rows - table.column("read_error").null_count
    err.print(f"{table.num_rows} recordings -> {output}"
              + (f" ({failed} could not be read)" if failed else ""))
    raise typer.Exit(3 if failed else 0)
