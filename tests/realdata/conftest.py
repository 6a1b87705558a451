"""The real-file suite: every importer run over files other tools wrote (`../shared/data/`).

One test module per source kind (`test_<kind>.py`) parametrises over every matching file with
``helpers_realdata.real_files``. A test converts, validates (no error findings unless the file itself
is defective, and then the finding is asserted), exports and re-imports, and checks plausibility
against the source (object and frame counts, positions on the map, speeds and sizes within the
class's range).
"""

from __future__ import annotations

from pathlib import Path

from helpers_common import realdata_fixture, shared


@realdata_fixture
def shared_data() -> Path:
    """``../shared/data`` (skips without it)."""
    return shared("data")
