"""The typer application: global options and the registration of every command module.

Command modules (``aveas_format/cli/*.py`` and those of partner packages, entry-point group
``aveas_format.commands``) are imported through :mod:`aveas_format.plugins`; each registers itself on
:data:`app` with ``@app.command()`` or ``app.add_typer(...)``. A name can be registered once: a
plugin cannot replace a built-in command.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import typer
import typer.main

from aveas_format import plugins
from aveas_format._version import __version__
from aveas_format.cli.common import State, fail
from aveas_format.errors import PluginError


class _App(typer.Typer):
    """A typer app that refuses a second command or group of the same name, naming both modules."""

    def _claim(self, name: str, module: str) -> None:
        owners: dict[str, str] = self.__dict__.setdefault("_owners", {})
        if name in owners:
            raise ValueError(f"command {name!r} of {module} registered twice: {owners[name]} has it")
        owners[name] = module

    def command(self, name: str | None = None, **kw: Any) -> Callable[[Callable], Callable]:
        register = super().command(name, **kw)

        def claim(fn: Callable) -> Callable:
            self._claim(name or typer.main.get_command_name(fn.__name__), fn.__module__)
            return register(fn)

        return claim

    def add_typer(self, typer_instance: typer.Typer, **kw: Any) -> None:
        name = kw.get("name")
        name = name if isinstance(name, str) else typer_instance.info.name
        if isinstance(name, str):
            self._claim(name, sys._getframe(1).f_globals.get("__name__", "?"))
        super().add_typer(typer_instance, **kw)


app = _App(
    name="aveas-format",
    help="The unified format of map-referenced trajectories (AVEAS): inspect, validate, convert, "
    "derive.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
)

#: the error of a command plugin that could not be loaded: every command reports it
_broken: list[PluginError] = []


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
    if _broken:
        raise fail(str(_broken[0]))


def _register_commands() -> None:
    """Import every command module, built-in and of plugins (each registers itself on ``app``).
    A plugin that cannot be loaded is kept in ``_broken``: importing the app still works (docs,
    tests), and every command fails with the plugin's one-line error."""
    try:
        plugins.load("commands")
    except PluginError as e:
        _broken.append(e)


_register_commands()
