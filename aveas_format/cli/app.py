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
    rich_markup_mode="markdown",
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


def _register_commands() -> None:
    """Import every command module of this package; each registers itself on ``app``."""
    import importlib
    import pkgutil

    import aveas_format.cli as pkg

    for mod in sorted(m.name for m in pkgutil.iter_modules(pkg.__path__)):
        if mod not in ("app", "common"):
            importlib.import_module(f"aveas_format.cli.{mod}")


_register_commands()
