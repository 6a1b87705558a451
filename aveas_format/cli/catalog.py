"""``aveas-format catalog DATASET -o catalog.parquet``: one row per recording, to search an archive
with DuckDB, Polars or pyarrow."""

from __future__ import annotations

from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors
from aveas_format.cli.options import (
    check_output,
    check_rules,
    comma_list,
    dataset_argument,
    discover_dataset,
    ignore_option,
    overwrite_option,
    print_failure,
    scheduler_option,
    select_option,
    validate_option,
    workers_option,
)


@app.command()
@handle_errors
def catalog(
    dataset: list[str] = dataset_argument(),
    output: Path = typer.Option(..., "--output", "-o", help="The catalog file: .parquet "
                                "(default), .csv or .jsonl."),
    validate: bool = validate_option(help="Run the validator for the validity columns (errors, "
                                     "warnings, valid)."),
    select: list[str] = select_option(help="Validate only these rules."),
    ignore: list[str] = ignore_option(help="Skip these rules."),
    workers: int = workers_option(),
    scheduler: str = scheduler_option(),
    overwrite: bool = overwrite_option(help="Replace OUTPUT if it exists."),
) -> None:
    """Catalog a dataset: one row per recording (id, partner, method, provenance, site, start
    time, duration, participants per class, rate, coverage area, validity, criticality) from
    recording.json and small tables only. Exit 3 when a recording could not be read (it still
    gets a row, with `read_error`)."""
    from aveas_format.dataset import catalog as build
    from aveas_format.dataset import write_catalog

    check_output(output, overwrite)
    only, skip = comma_list(select), comma_list(ignore)
    if validate:
        check_rules(only, skip)
    paths = discover_dataset(dataset, "cataloguing", workers, scheduler)
    table = build(paths, validate=validate, workers=workers or None, scheduler=scheduler,
                  progress=True, select=only, ignore=skip, on_result=print_failure)
    write_catalog(table, output)
    failed = table.num_rows - table.column("read_error").null_count
    err.print(f"{table.num_rows} recordings -> {output}"
              + (f" ({failed} could not be read)" if failed else ""))
    raise typer.Exit(3 if failed else 0)
