"""The command-line interface ``aveas-format`` (typer + rich), one module per command."""

from __future__ import annotations

import sys

from aveas_format.cli.app import app


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``aveas-format`` script."""
    app(args=argv if argv is not None else sys.argv[1:], prog_name="aveas-format")


__all__ = ["app", "main"]
