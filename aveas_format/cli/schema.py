"""``aveas-format schema``: the JSON Schema of recording.json, or the table spec."""

from __future__ import annotations

import json

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import handle_errors


@app.command()
@handle_errors
def schema(
    tables: bool = typer.Option(False, "--tables", help="Print the machine-readable spec of every "
                                "table (columns, types, units, ranges, requirement) instead."),
) -> None:
    """Print the JSON Schema of recording.json (or, with --tables, the table spec) to stdout."""
    from aveas_format.schema import recording_json_schema, tables_spec

    print(json.dumps(tables_spec() if tables else recording_json_schema(), indent=2))
