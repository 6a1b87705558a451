"""Fixtures of the interoperability tests: a rich recording, the official schemas."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from helpers import rich_recording  # noqa: E402


@pytest.fixture(scope="session")
def rich():
    return rich_recording()


@pytest.fixture(scope="session")
def openlabel_schema():
    uai = pytest.importorskip("uai_openlabel")
    return json.loads((Path(uai.__file__).parent / "official_schema" / "openlabel_json_schema.json").read_text())
