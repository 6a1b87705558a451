"""Generated reference docs are in sync with the code."""

from __future__ import annotations

import pytest

from docgen import generated


@pytest.mark.parametrize("path,text", list(generated().items()), ids=lambda v: getattr(v, "name", ""))
def test_generated_doc_is_up_to_date(path, text):
    assert path.exists(), f"{path} missing: run `make docs`"
    assert path.read_text(encoding="utf-8") == text, f"{path.name} is stale: run `make docs`"
