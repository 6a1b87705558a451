"""Fixtures of the validation tests: the clean recording of the fixture factory."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

# test_rule_corpus is imported by name by test_streaming and test_validate_reports
sys.path.insert(0, str(Path(__file__).resolve().parent))

import helpers_validate as vf  # noqa: E402


@pytest.fixture
def scene():
    return vf.fresh()


@pytest.fixture(scope="session")
def clean():
    """The clean recording (session-wide: do not mutate)."""
    return vf.build(vf.fresh())
