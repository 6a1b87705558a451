"""The command-line interface ``aveas-format`` (typer + rich), one module per command."""

from __future__ import annotations

import sys

from aveas_format.cli.app import app


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``aveas-format`` script: runs the app and exits with its code
    (:func:`aveas_format.cli.common.run` keeps the CLI contract of docs/cli.md)."""
    from aveas_format.cli.common import run

    sys.exit(run(app, argv if argv is not None else sys.argv[1:]))


__all__ = ["app", "main"]
