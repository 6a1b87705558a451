"""The typer application: global options and the registration of every command module."""

from __future__ import annotations

import typer

from aveas_format._version import __version__
from aveas_format.cli.common import State

app = typer.Typer(
    name="aveas-format",
    help="The unified format of map-referenced trajectories (AVEAS): inspect, validate, convert, "
    "derive.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)


def _version(value: bool) -> None:
    if value:
        print(f"aveas-format {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
    debug: bool = typer.Option(False, "--debug", help="Show tracebacks of errors."),
) -> None:
    State.debug = debug


# command modules register themselves on `app`
from aveas_format.cli import demo, info, schema, validate  # noqa: E402,F401
