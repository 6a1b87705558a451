"""Format versions and migrations (STYLE.md 7: identify, migrate, load).

A migration is one small function per step, registered with :func:`migration`; it takes the
recording.json dict of version ``from_version`` and returns it at ``to_version``. Table-level changes
get the same hook through ``table_migrations``: ``{(from, to): {table_name: fn(table) -> table}}``,
applied by ``aveas_format.io`` (this layer imports no pyarrow, so those functions live with their
step but are called from io).

No version before 1.0.0 exists; the mechanism is exercised by the tests with a frozen 1.0.0 example
and by a test-only migration step registered temporarily.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any

FORMAT_VERSION = "1.0.0"
#: Versions this library can read (possibly after migration), oldest first.
KNOWN_VERSIONS: list[str] = ["1.0.0"]

MetaMigration = Callable[[dict[str, Any]], dict[str, Any]]
#: (from_version, to_version) -> metadata migration
MIGRATIONS: dict[tuple[str, str], MetaMigration] = {}
#: (from_version, to_version) -> {table name: table migration (pyarrow.Table -> pyarrow.Table)}
TABLE_MIGRATIONS: dict[tuple[str, str], dict[str, Callable[[Any], Any]]] = {}

_SEMVER = re.compile(r"^(0|[1-9]\d*)\.(0|[1-9]\d*)\.(0|[1-9]\d*)$")


class VersionError(ValueError):
    """Raised by this module; io wraps it in FormatVersionError with the file name."""


def parse_version(v: object) -> tuple[int, int, int]:
    if not isinstance(v, str) or not _SEMVER.match(v):
        raise VersionError(f"format_version must be a semantic version like '1.0.0', got {v!r}")
    major, minor, patch = (int(p) for p in v.split("."))
    return major, minor, patch


def migration(from_version: str, to_version: str,
              tables: dict[str, Callable[[Any], Any]] | None = None
              ) -> Callable[[MetaMigration], MetaMigration]:
    """Register a migration step (decorator)."""

    def register(fn: MetaMigration) -> MetaMigration:
        MIGRATIONS[(from_version, to_version)] = fn
        if tables:
            TABLE_MIGRATIONS[(from_version, to_version)] = dict(tables)
        return fn

    return register


def migration_path(version: str) -> list[tuple[str, str]]:
    """The chain of steps from ``version`` to :data:`FORMAT_VERSION` ([] if already current).

    Raises VersionError for malformed versions, versions newer than this library (with the same
    major version, a newer minor or patch is read as is: additive changes only) and versions no
    chain of migrations leads from.
    """
    current = parse_version(FORMAT_VERSION)
    given = parse_version(version)
    if given == current:
        return []
    if given[0] > current[0]:
        raise VersionError(
            f"format_version {version} is newer than this library supports ({FORMAT_VERSION}); "
            "upgrade aveas-format"
        )
    if given[0] == current[0] and given > current:
        return []  # newer minor/patch of the same major: additive, readable as is
    steps: list[tuple[str, str]] = []
    at = version
    seen = {at}
    while at != FORMAT_VERSION:
        nxt = [to for (frm, to) in MIGRATIONS if frm == at]
        if not nxt:
            raise VersionError(f"format_version {version} is not supported and no migration leads from it")
        to = max(nxt, key=parse_version)
        if to in seen:
            raise VersionError(f"migration cycle at {to}")
        steps.append((at, to))
        seen.add(to)
        at = to
    return steps


def migrate_meta(meta: dict[str, Any]) -> tuple[dict[str, Any], list[tuple[str, str]]]:
    """Migrate a recording.json dict in memory; return it and the steps applied."""
    steps = migration_path(meta.get("format_version"))  # type: ignore[arg-type]
    for step in steps:
        meta = MIGRATIONS[step](dict(meta))
        meta["format_version"] = step[1]
    return meta, steps
