"""Shared fixtures (helpers live in tests/aveas_testing.py)."""

from __future__ import annotations

import pytest

from aveas_testing import CONFORMANCE, small_recording


@pytest.fixture
def rec():
    return small_recording()


@pytest.fixture
def written(tmp_path, rec):
    """A small recording written in directory form."""
    return rec.write(tmp_path / "small.aveas")


@pytest.fixture(scope="session")
def conformance_path():
    if not CONFORMANCE.is_dir():
        pytest.skip(f"shared conformance recording not found at {CONFORMANCE}")
    return CONFORMANCE
