"""aveas_format — the unified format of map-referenced trajectories (AVEAS).

>>> import aveas_format
>>> rec = aveas_format.open("highway.aveas")          # directory or .aveas.zip
>>> rec.states.num_rows, rec.meta.acquisition.method
>>> report = aveas_format.validate(rec)
>>> rec.write("copy.aveas.zip")

The heavy parts (pyarrow, the rule engine) load on first use, so ``import aveas_format.schema``
stays free of pyarrow, lxml and pyproj.
"""

from __future__ import annotations

import importlib
from typing import Any

from aveas_format._version import __version__
from aveas_format.errors import (
    AveasError,
    ChecksumError,
    FormatError,
    FormatVersionError,
    MapError,
    MissingDependencyError,
    RecordingExistsError,
    RecordingIOError,
    UsageError,
)

_LAZY = {
    "open": ("aveas_format.io.reader", "open_recording"),
    "Recording": ("aveas_format.io.recording", "Recording"),
    "ReadPlan": ("aveas_format.io.reader", "ReadPlan"),
    "build_recording": ("aveas_format.mapref.build", "build_recording"),
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        module, attr = _LAZY[name]
        value = getattr(importlib.import_module(module), attr)
        globals()[name] = value
        return value
    if name == "validate":
        # the validation package; the module object is callable:
        # ``aveas_format.validate(path_or_recording, ...) -> Report``
        return importlib.import_module("aveas_format.validate")
    raise AttributeError(f"module 'aveas_format' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names with the lazily loaded ones (``open``, ``validate``, ``Recording``...),
    which ``dir()`` and tab completion would otherwise miss until first use."""
    return sorted(set(globals()) | set(_LAZY) | {"validate"})


__all__ = [
    "AveasError", "ChecksumError", "FormatError", "FormatVersionError", "MapError",
    "MissingDependencyError", "ReadPlan", "Recording", "RecordingExistsError", "RecordingIOError",
    "UsageError", "__version__", "build_recording", "open", "validate",
]
