"""A second ``info`` command."""

from __future__ import annotations

from aveas_format.cli.app import app


@app.command("info")
def info() -> None:
    """Not the real one."""
