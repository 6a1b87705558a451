"""Helpers of the real-file suite (tests/realdata/): the files other tools wrote, under ../shared/data.

One test module per source kind (``tests/realdata/test_<kind>.py``) parametrises over every
matching file with :func:`real_files`; each parameter carries the marker ``realdata``, and without
``../shared`` beside the checkout the test is skipped with the one reason
:data:`helpers_common.SHARED_ABSENT`.
"""

from __future__ import annotations

from helpers_common import SHARED, SHARED_ABSENT, realdata_params

DATA = SHARED / "data"
REAL = DATA / "real"
ABSENT = SHARED_ABSENT


def real_files(*patterns: str) -> list:
    """``pytest.param(path, id=...)`` (marked ``realdata``) for every file under
    ``../shared/data`` matching one of the glob ``patterns`` (relative to ``../shared/data``),
    sorted; one skipped param when the folder is absent, so that parametrised tests report one
    clear reason."""
    paths = sorted({p for pat in patterns for p in DATA.glob(pat) if p.is_file()})
    return realdata_params(paths, ids=lambda p: str(p.relative_to(DATA)))
