"""Module-level task functions for tests/dataset (picklable by worker processes and Dask: they
import this module by name, which works because tests/ is on sys.path and spawned workers inherit it)."""

from __future__ import annotations

import os

from aveas_format.dataset import validate_recording


def validate_or_crash(path: str) -> dict:
    """validate_recording, except that a recording named ``poison*`` kills its worker process."""
    if os.path.basename(path.rstrip("/")).startswith("poison"):
        os._exit(13)  # the worker dies without a Python exception
    return validate_recording(path)
