"""Shared pieces of the CLI: the consoles, exit codes, error handling and the outer layer of every
run (the options several commands share are declared in :mod:`aveas_format.cli.options`).

The contract (docs/cli.md), kept here once for every command:

- exit codes 0 ok, 1 findings, 2 usage (:class:`~aveas_format.errors.UsageError`, typer's own
  usage errors, ``--overwrite`` refusals), 3 unreadable input or tool failure;
- every error is one line on stderr, ``aveas-format: error: ...``, never a traceback (unless
  ``--debug``); a wrong option *value* gets the closest allowed one (``did you mean 'html'?``);
- a closed pipe (``aveas-format info REC | head -1``) is not an error: silent, exit 0;
- output that is not a terminal is plain: help without boxes and with every option name whole,
  tables as aligned text (:func:`print_table`);
- numbers in messages are rounded for people (:func:`aveas_format.numeric.fmt_num`).
"""

from __future__ import annotations

import functools
import os
import re
import sys
import traceback
import warnings
from collections.abc import Callable, Sequence
from enum import Enum
from typing import Any, TypeVar

import typer
from rich.console import Console

from aveas_format.errors import AveasError, UsageError, did_you_mean


class _Console(Console):
    """A rich console whose closed pipe is the CLI's (a silent exit 0), not rich's exit 1."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        raise BrokenPipeError


#: machine output (JSON, reports) goes to stdout; messages and errors to stderr. Without markup:
#: messages carry paths and library text (``pip install "aveas-format[plot]"``) that rich would
#: read as tags; a call that styles passes ``markup=True`` and escapes what it interpolates.
out = _Console(highlight=False, soft_wrap=True, markup=False)
err = _Console(stderr=True, highlight=False, soft_wrap=True, markup=False)

EXIT_OK = 0
EXIT_FINDINGS = 1
EXIT_USAGE = 2
EXIT_UNREADABLE = 3
PROG = "aveas-format"


class State:
    debug = False


F = TypeVar("F", bound=Callable[..., Any])


def fail(message: str, code: int = EXIT_UNREADABLE) -> typer.Exit:
    """Print one clear line on stderr and return the Exit to raise."""
    print(f"{PROG}: error: {' '.join(str(message).split())}", file=sys.stderr)
    return typer.Exit(code)


def _closed_pipe() -> typer.Exit:
    """stdout was closed by the reader (``| head``): stop quietly. Further writes (the
    interpreter's final flush included) go to /dev/null, as the Python docs recommend."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout without a file descriptor (tests): nothing to redirect
        pass
    return typer.Exit(EXIT_OK)


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    err.print(f"warning: {message}", markup=False)


def handle_errors(fn: F) -> F:
    """Turn library errors into one line on stderr + exit 3 (2 for a usage error), a closed pipe
    into a silent exit 0; never a traceback unless ``--debug``."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            with warnings.catch_warnings():
                if not State.debug:  # a library warning is one line, without its source line
                    warnings.showwarning = _show_warning
                return fn(*args, **kwargs)
        except (typer.Exit, typer.Abort):
            raise
        except BrokenPipeError:
            raise _closed_pipe() from None
        except UsageError as e:
            if State.debug:
                traceback.print_exc()
            raise fail(str(e), EXIT_USAGE) from None
        except AveasError as e:
            if State.debug:
                traceback.print_exc()
            raise fail(str(e)) from None
        except OSError as e:  # (after BrokenPipeError) a file the library did not name itself
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


# ----------------------------------------------------------------------------------------------
# plain output when not a terminal
def is_terminal() -> bool:
    """Whether stdout is a terminal (rich tables and help boxes) or not (plain text)."""
    return out.is_terminal


def print_table(rows: Sequence[Sequence[Any]], columns: Sequence[str] | None = None, *,
                title: str | None = None, right: Sequence[int] = ()) -> None:
    """Rows as a rich table on a terminal; elsewhere (a pipe, a file) as plain text in aligned
    columns, every value whole (no ellipses). ``columns``: header (None: a key/value list);
    ``right``: indices of right-aligned columns."""
    cells = [[str(v) for v in row] for row in rows]
    if is_terminal():  # (the console reads no markup: cells are shown as they are)
        from rich.table import Table

        t = Table(title=title, show_header=columns is not None, show_edge=False,
                  box=None if columns is None else Table().box, pad_edge=columns is not None)
        for i, name in enumerate(columns or [""] * (len(cells[0]) if cells else 0)):
            t.add_column(name, justify="right" if i in right else "left",
                         style="bold" if columns is None and i == 0 else None, overflow="fold")
        for row in cells:
            t.add_row(*row)
        out.print(t)
        return
    lines = ([list(columns)] if columns else []) + cells
    if not lines:
        return
    widths = [max(len(r[i]) for r in lines if i < len(r)) for i in range(max(map(len, lines)))]
    if title:
        print(title)
    for r in lines:
        parts = [c.rjust(widths[i]) if i in right else c.ljust(widths[i]) for i, c in enumerate(r)]
        print("  ".join(parts).rstrip())


# ----------------------------------------------------------------------------------------------
# the outer layer of a run: usage errors in one line, closed pipes, plain help
def _exceptions() -> Any:
    """The click exception module typer uses (the installed click, or typer's vendored copy)."""
    return sys.modules[typer.BadParameter.__module__]


def _choices(param: Any) -> list[str]:
    """The allowed values of a choice parameter (an Enum annotation, or a click Choice)."""
    ann = getattr(getattr(param, "type_descriptor", None), "annotation", None)
    if isinstance(ann, type) and issubclass(ann, Enum):
        return [str(m.value) for m in ann]
    return [str(c) for c in getattr(getattr(param, "type", None), "choices", None) or ()]


def usage_message(e: Exception) -> str:
    """typer's usage error as one line, with the closest allowed value of a wrong choice and
    where to find help: ``Invalid value for '--format': 'htm' is not one of 'text', 'json',
    'html' (did you mean 'html'?); see 'aveas-format validate --help'``."""
    msg = " ".join(e.format_message().split())  # type: ignore[attr-defined]
    msg = msg.replace("Value error, ", "")
    param = getattr(e, "param", None)
    bad = re.search(r"'([^']*)' is not (?:one of )?'", msg)
    if param is not None and bad:
        msg = msg.rstrip(".") + did_you_mean(bad.group(1), _choices(param))
    ctx = getattr(e, "ctx", None)
    where = getattr(ctx, "command_path", None) or PROG
    return f"{msg.rstrip('.')}; see '{where} --help'"


def _plain_help(command: Any) -> None:
    """Help without rich boxes for every command (not a terminal): click's own formatter, which
    wraps descriptions and never truncates option names; a group lists its commands by the first
    sentence of their help, whole (not cut at 45 characters with an ellipsis)."""
    if hasattr(command, "rich_markup_mode"):
        command.rich_markup_mode = None
    for sub in getattr(command, "commands", {}).values():
        if not getattr(sub, "short_help", None) and getattr(sub, "help", None):
            first = re.split(r"(?<=[.:])\s", " ".join(sub.help.split()), maxsplit=1)[0]
            sub.short_help = first.rstrip(".:")
        _plain_help(sub)


def run(app: typer.Typer, args: Sequence[str]) -> int:
    """Run the app on ``args`` and return the exit code, keeping the contract of the module
    docstring for what typer handles itself (parsing, help)."""
    import typer.main

    exc = _exceptions()
    command = typer.main.get_command(app)
    if not is_terminal():
        _plain_help(command)
    try:
        code = command.main(args=list(args), prog_name=PROG, standalone_mode=False)
    except BrokenPipeError:
        code = _closed_pipe().exit_code
    except exc.UsageError as e:
        if type(e).__name__ == "NoArgsIsHelpError":  # `aveas-format` alone: the help
            text = e.format_message()
            if text:  # (rich help was printed while the error was made)
                print(text)
            return EXIT_USAGE
        print(f"{PROG}: error: {usage_message(e)}", file=sys.stderr)
        return EXIT_USAGE
    except exc.ClickException as e:
        print(f"{PROG}: error: {' '.join(e.format_message().split())}", file=sys.stderr)
        return e.exit_code
    except (getattr(exc, "Abort", typer.Abort), typer.Abort, KeyboardInterrupt):
        print(f"{PROG}: error: interrupted", file=sys.stderr)
        return 130
    except SystemExit:  # click's own handling of a closed pipe (while printing help): exit 1
        if type(sys.stdout).__name__ == "PacifyFlushWrapper":
            return EXIT_OK
        raise
    return code if isinstance(code, int) else EXIT_OK
