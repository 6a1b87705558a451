"""Helpers of the real-file suite (tests/realdata/): the files other tools wrote, under ../shared/data.

One test module per source kind (``tests/realdata/test_<kind>.py``) parametrises over every
matching file with :func:`real_files`; without ``../shared`` beside the checkout each such test is
skipped with one reason.
"""

from __future__ import annotations

import pytest

from helpers_common import SHARED

DATA = SHARED / "data"
REAL = DATA / "real"
ABSENT = f"real-file suite: the shared data folder is not at {DATA} (clone ../shared beside the checkout)"


def real_files(*patterns: str) -> list:
    """``pytest.param(path, id=...)`` for every file under ``../shared/data`` matching one of the
    glob ``patterns`` (relative to ``../shared/data``), sorted; one skipped param when the folder is
    absent, so that parametrised tests report one clear reason."""
    if not DATA.is_dir():
        return [pytest.param(None, id="shared-data-absent", marks=pytest.mark.skip(reason=ABSENT))]
    paths = sorted({p for pat in patterns for p in DATA.glob(pat) if p.is_file()})
    return [pytest.param(p, id=str(p.relative_to(DATA))) for p in paths]
