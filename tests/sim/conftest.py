"""Fixtures of the SUMO runner/fitter tests: skip when SUMO is not installed."""

from __future__ import annotations

import pytest

from aveas_format.sim import SumoNotFoundError, find_sumo


@pytest.fixture(scope="session")
def sumo():
    try:
        return find_sumo("sumo")
    except SumoNotFoundError:
        pytest.skip('SUMO not installed (pip install "aveas-format[sim]")')
