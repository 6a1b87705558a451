"""Fixtures of the converter tests: a rich recording (for the OpenLABEL, OpenSCENARIO and MCAP
exports), the official OpenLABEL schema."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers_common import realdata_fixture, shared
from helpers_converters import rich_recording


@realdata_fixture
def openlabel_data() -> Path:
    """The OpenLABEL files of ../shared/data/openlabel (ASAM, VCD and AVEAS examples)."""
    return shared("data", "openlabel")


@pytest.fixture(scope="session")
def rich():
    return rich_recording()


@pytest.fixture(scope="session")
def openlabel_schema():
    uai = pytest.importorskip("uai_openlabel")
    return json.loads((Path(uai.__file__).parent / "official_schema" / "openlabel_json_schema.json").read_text())
