"""Shared pieces of the CLI: the consoles, exit codes and error handling (the options several
commands share are declared in :mod:`aveas_format.cli.options`)."""

from __future__ import annotations

import functools
import sys
import traceback
import warnings
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


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    err.print(f"warning: {message}", markup=False)


def handle_errors(fn: F) -> F:
    """Turn library errors into one line on stderr + exit 3 (2 for usage), never a traceback
    unless ``--debug``."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            with warnings.catch_warnings():
                if not State.debug:  # a library warning is one line, without its source line
                    warnings.showwarning = _show_warning
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
