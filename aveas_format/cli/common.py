"""Shared pieces of the CLI: the console, error handling, options."""

from __future__ import annotations

import functools
import json
import sys
import traceback
import typing
from pathlib import Path
from collections.abc import Callable
from typing import Any, TypeVar

import typer
from rich.console import Console

from aveas_format.errors import AveasError

#: machine output (JSON, reports) goes to stdout; messages and errors to stderr
out = Console(highlight=False, soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)

EXIT_FINDINGS = 1
EXIT_USAGE = 2
EXIT_UNREADABLE = 3


class State:
    debug = False


F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str, code: int = EXIT_UNREADABLE) -> typer.Exit:
    """Print one clear line on stderr and return the Exit to raise."""
    print(f"aveas-format: error: {message}", file=sys.stderr)
    return typer.Exit(code)


def handle_errors(fn: F) -> F:
    """Turn library errors into one line on stderr + exit 3 (2 for usage), never a traceback
    unless ``--debug``."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except AveasError as e:
            if State.debug:
                traceback.print_exc()
            raise fail(str(e)) from None
        except (FileExistsError, PermissionError, IsADirectoryError, FileNotFoundError) as e:
            if State.debug:
                traceback.print_exc()
            raise fail(f"{e.filename or ''}: {e.strerror or e}".lstrip(": ")) from None
        except KeyboardInterrupt:
            raise fail("interrupted", 130) from None
        except Exception as e:  # noqa: BLE001 — the CLI's last line of defence
            if State.debug:
                traceback.print_exc()
            raise fail(f"internal error: {type(e).__name__}: {e} (run with --debug for the "
                       "traceback and please report it)") from None

    return wrapper  # type: ignore[return-value]


def parse_option_pairs(pairs: list[str], model: type) -> dict[str, Any]:
    """``["net_file=a.net.xml", "vtypes=a.rou.xml,b.rou.xml", "geo=true"]`` -> dict.

    Values are read as JSON where they parse (numbers, booleans, lists), else as strings; a
    comma-separated string becomes a list for list-typed options.
    """
    out_: dict[str, Any] = {}
    fields = getattr(model, "model_fields", {})
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--option {pair!r}: expected KEY=VALUE")
        key, raw = pair.split("=", 1)
        key = key.strip().replace("-", "_")
        try:
            value: Any = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        ann = fields[key].annotation if key in fields else None
        if typing.get_origin(ann) in (list, tuple) and isinstance(value, str):
            value = [v for v in value.split(",") if v]
        out_[key] = value
    return out_


def converter_options(options_file: Path | None, pairs: list[str] | None, model: type) -> dict[str, Any]:
    """Options of a converter/exporter from ``--options FILE.json`` and ``-O KEY=VALUE`` pairs
    (pairs win); a usage error (exit 2) when the file or a pair cannot be read."""
    raw: dict[str, Any] = {}
    if options_file:
        try:
            raw.update(json.loads(options_file.read_text()))
        except (OSError, json.JSONDecodeError) as e:
            raise fail(f"{options_file}: cannot read options: {e}", EXIT_USAGE) from None
    try:
        raw.update(parse_option_pairs(pairs or [], model))
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None
    return raw
