"""Fixtures shared by more than one test folder (helper functions live in tests/helpers_*.py; see
tests/README.md)."""

from __future__ import annotations

import pytest

from helpers_common import CONFORMANCE, small_recording


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


@pytest.fixture(scope="session")
def sumo():
    """The SUMO binary of the runner and fitter tests (tests/sim, tests/fit); skips without SUMO."""
    from aveas_format.sim import SumoNotFoundError, find_sumo

    try:
        return find_sumo("sumo")
    except SumoNotFoundError:
        pytest.skip('SUMO not installed (pip install "aveas-format[sim]")')
