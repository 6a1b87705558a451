"""The exception hierarchy of aveas_format.

Every error raised on purpose by the library derives from :class:`AveasError`. Errors are also
built-in exceptions so that callers can catch either (STYLE.md 11, as rasterio does):

- :class:`RecordingIOError` (also :class:`OSError`): a file is missing, unreadable or truncated.
- :class:`FormatError` (also :class:`ValueError`): the content violates the format.
- :class:`FormatVersionError`: an unknown or unsupported ``format_version``.
- :class:`ChecksumError`: a table or the map does not match the SHA-256 in recording.json.
- :class:`MapError` (also :class:`ValueError`): an OpenDRIVE map cannot be read; carries the XML line.
- :class:`PluginError` (also :class:`ImportError`): a plugin (an entry point of a partner package)
  cannot be loaded or registers a name that exists (:mod:`aveas_format.plugins`).
- :class:`UsageError` (also :class:`ValueError`): the call itself is wrong (an unknown converter,
  exporter, option or value; a missing map), not the data; the CLI exits 2 with it.
- :class:`MissingDependencyError` (also :class:`ImportError`): an optional dependency is not
  installed; the message names the extra that brings it (:func:`require`).

Two helpers go with them: :func:`require` imports an optional dependency or raises
:class:`MissingDependencyError` naming the extra (``pip install "aveas-format[ros2]"``), the one
guard of every optional import; :func:`did_you_mean` adds the closest known name to a message
about an unknown one.

Findings about a source file that an import survives (a dropped box, a PMF not summing to 1) are
not errors: a converter reports each with :func:`report_source` — a warning by default, a located
:class:`SourceFinding` when the caller listens (:func:`collect_source_findings`, as
``aveas-format validate FILE`` does, which turns them into the ``source.*`` rules' findings).

Each error carries the ``path`` it is about (and, where known, ``line``/``row``/``column``) as
attributes, and its message names them: the CLI prints ``str(error)`` as its one line on stderr.

This module imports nothing outside the standard library: every layer may use it.
"""

from __future__ import annotations

import difflib
import importlib
import warnings
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import PurePath
from types import ModuleType
from typing import Any


class AveasError(Exception):
    """Base class of every error raised on purpose by aveas_format."""

    def __init__(self, message: str, *, path: str | PurePath | None = None, **where: object) -> None:
        self.message = message
        self.path = str(path) if path is not None else None
        self.where = {k: v for k, v in where.items() if v is not None}
        super().__init__(self._render())

    def _render(self) -> str:
        prefix = f"{self.path}: " if self.path else ""
        loc = ", ".join(f"{k} {v}" for k, v in self.where.items())
        return f"{prefix}{loc + ': ' if loc else ''}{self.message}"

    def __str__(self) -> str:  # OSError overrides __str__; keep ours
        return self._render()


class RecordingIOError(AveasError, OSError):
    """A file of a recording (or a map) is missing, unreadable, truncated or not writable."""


class FormatError(AveasError, ValueError):
    """The content of a recording violates the format (wrong type, bad JSON, bad metadata...)."""


class FormatVersionError(FormatError):
    """The recording's ``format_version`` is unknown, newer than this library, or malformed."""


class ChecksumError(FormatError):
    """A file's SHA-256 or row count differs from what recording.json declares."""


class MapError(AveasError, ValueError):
    """An OpenDRIVE map is malformed; ``line`` names the XML line where known."""


class RecordingExistsError(AveasError, FileExistsError):
    """The output exists and ``overwrite`` was not given."""


class PluginError(AveasError, ImportError):
    """A plugin cannot be imported, or registers a converter, rule, derivation, table or command
    under a name that exists; the message names the entry point and its distribution."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.path = None  # ImportError.__init__ resets it; a plugin error is about no file


class UsageError(AveasError, ValueError):
    """The call is wrong, not the data: an unknown converter, exporter, option or value, or a
    missing argument (a map the converter needs). The CLI exits 2 with it."""


class MissingCrsError(FormatError, UsageError):
    """The map has no ``<geoReference>`` and no ``crs`` was given: the recording's frame is
    undefined (FORMAT.md: ``crs`` alone defines it then). The converter registry turns it into a
    message showing the command that works. A missing argument: the CLI exits 2 with it."""


class MissingDependencyError(AveasError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it."""

    def __init__(self, message: str, *, module: str, extra: str) -> None:
        super().__init__(message)
        self.path = None  # ImportError.__init__ resets it; the error is about no file
        self.module, self.extra = module, extra


def require(module: str, *, extra: str, what: str | None = None) -> ModuleType:
    """Import the optional dependency ``module`` and return it; without it, a
    :class:`MissingDependencyError` in one line naming the extra, e.g. ``mcap, an optional
    dependency for the mcap export, is not installed: pip install "aveas-format[mcap]"``.
    ``what`` names the feature (default: the extra)."""
    try:
        return importlib.import_module(module)
    except ImportError as e:
        missing = getattr(e, "name", None) or module
        raise MissingDependencyError(
            f"{missing}, an optional dependency for {what or 'aveas-format[' + extra + ']'}, is "
            f'not installed: pip install "aveas-format[{extra}]"', module=missing,
            extra=extra) from None


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``" (did you mean 'sumo-fcd'?)"`` for the closest of ``known`` to ``name``, else ``""``."""
    close = difflib.get_close_matches(str(name), [str(k) for k in known], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


__all__ = [
    "AveasError",
    "ChecksumError",
    "FormatError",
    "FormatVersionError",
    "MapError",
    "MissingDependencyError",
    "PluginError",
    "RecordingExistsError",
    "RecordingIOError",
    "UsageError",
    "did_you_mean",
    "require",
]


# --- findings about a source file, reported while it is imported ---------------------------------

@dataclass(frozen=True)
class SourceFinding:
    """Something wrong with a foreign file that the import survived (a box with an impossible size
    dropped, a PMF not summing to 1, an unknown object type...), located in the source's own terms.

    ``code`` is the code of the validate rule that reports it (``source.*``, see
    ``validate/rules/source.py``); ``location`` holds the source's own coordinates of the problem:
    ``file``, ``line`` (1-based, XML/JSON text), ``frame`` (OpenLABEL frame key), ``uid`` (OpenLABEL
    object uid), ``json_path``, ``message_index`` / ``object_id`` (OSI), ``entity`` (OpenSCENARIO),
    ``participant_id`` / ``time`` (the format's). ``count`` says how many instances the one finding
    stands for (a vectorised check reports the first location and the count)."""

    code: str
    message: str
    location: dict[str, Any] = field(default_factory=dict)
    count: int = 1


_SOURCE_COLLECTOR: ContextVar[list[SourceFinding] | None] = ContextVar("aveas_source_findings",
                                                                       default=None)


def report_source(code: str, message: str, *, count: int = 1, stacklevel: int = 2,
                  **location: Any) -> None:
    """Report a finding about the file being imported: collected when a caller listens
    (:func:`collect_source_findings`, as ``aveas-format validate FILE`` does), otherwise a
    ``UserWarning`` with the location and the message (``FILE: line 12, entity 'Ego': ...``, what
    an import on its own has always shown)."""
    sink = _SOURCE_COLLECTOR.get()
    if sink is not None:
        sink.append(SourceFinding(code, message, {k: v for k, v in location.items() if v is not None},
                                  count))
    else:
        warnings.warn(_located(message, location), stacklevel=stacklevel + 1)


def _located(message: str, location: dict[str, Any]) -> str:
    """The warning of an uncollected source finding: its location first, as an error's message
    is (``trace.osi: message index 3, object id 7: ...``)."""
    where = {k: v for k, v in location.items() if v is not None
             and not (isinstance(v, str) and repr(v) in message)}  # the message names it
    file, line = where.pop("file", None), where.pop("line", None)
    head = f"{file}:{line}" if file and line is not None else file or (
        f"line {line}" if line is not None else "")
    loc = ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in where.items())
    return "".join(f"{p}: " for p in (head, loc) if p) + message


@contextmanager
def collect_source_findings() -> Iterator[list[SourceFinding]]:
    """``with collect_source_findings() as found: convert(...)`` — the import's findings land in
    ``found`` instead of being warned."""
    sink: list[SourceFinding] = []
    token = _SOURCE_COLLECTOR.set(sink)
    try:
        yield sink
    finally:
        _SOURCE_COLLECTOR.reset(token)
