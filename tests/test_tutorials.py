"""Every tutorial in docs/tutorials runs as written and produces the figures it shows (one that says
``<!-- slow: ... -->`` in `make test-all`)."""

from __future__ import annotations

import pytest

from docgen import DOCS, run_tutorial, tutorial_missing, tutorial_paths, tutorial_slow


def test_there_are_tutorials():
    assert len(tutorial_paths()) >= 4


@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if tutorial_slow(p) else p
                                  for p in tutorial_paths()], ids=lambda p: p.stem)
def test_tutorial_runs(path, tmp_path):
    why = tutorial_missing(path)
    if why:
        pytest.skip(why)
    figures = run_tutorial(path, tmp_path)
    for produced, committed in figures:
        assert produced.stat().st_size > 1000
        assert committed.exists(), f"{committed.name} missing: run `make docs`"
        assert f"../figures/{committed.name}" in path.read_text(encoding="utf-8")


def test_tutorial_figures_are_referenced():
    index = (DOCS / "tutorials" / "README.md").read_text(encoding="utf-8")
    for path in tutorial_paths():
        assert path.name in index, f"{path.name} not listed in docs/tutorials/README.md"
