"""A plain clone (the repository alone, no ``../shared`` beside it) collects and runs green: every
test that needs the real data skips with the one reason ``helpers_common.SHARED_ABSENT``, and
pytest's closing line says how many did.

The repository is copied into a temporary directory (which has no ``shared`` folder next to it)
and pytest runs there in a subprocess with this interpreter: the fast check collects every test
(an import-time read of ``../shared`` is a collection error) and runs the ``realdata`` tests; the
slow one (``make test-all``) runs the whole fast suite there.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from helpers_common import ROOT, SHARED, SHARED_ABSENT, shared

#: never copied: environments, caches, build and demo outputs
IGNORE = shutil.ignore_patterns(".venv", ".git", "__pycache__", ".pytest_cache", ".hypothesis",
                                "*.egg-info", "build", "dist", "demo-output")


def _plain_clone(dst: Path) -> Path:
    """The files of the checkout (tracked and new, as git sees them; all but IGNORE without git)
    copied to ``dst/repo``; ``dst`` has no ``shared`` folder."""
    repo = dst / "repo"
    try:
        names = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others",
                                "--exclude-standard"], capture_output=True, check=True,
                               timeout=60).stdout.decode().split("\0")
    except (OSError, subprocess.SubprocessError):
        shutil.copytree(ROOT, repo, ignore=IGNORE)
        return repo
    for name in filter(None, names):
        src = ROOT / name
        if src.is_file():
            (repo / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, repo / name)
    return repo


def _pytest(repo: Path, *args: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST", "PYTHONPATH"))}
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *args],
                          cwd=repo, env=env, capture_output=True, text=True, timeout=3600)


def _check(res: subprocess.CompletedProcess, parent: Path) -> str:
    """The run is green, its closing line counts the real-data tests skipped, and every skipped
    real-data test gives the one reason; returns the closing line."""
    out = res.stdout + res.stderr
    assert res.returncode == 0, out[-6000:]
    closing = out.strip().splitlines()[-1]
    assert "failed" not in closing and "error" not in closing, closing
    n = re.search(r"(\d+) real-data skipped \(no \.\./shared\)", closing)
    assert n and int(n.group(1)) > 50, closing
    assert "ran on real data" not in closing, closing
    reasons = {m.group(1) for m in re.finditer(r"SKIPPED \[\d+\] \S+: (real data: .*)", out)}
    assert reasons == {SHARED_ABSENT.replace(str(SHARED), str(parent / "shared"))}, reasons
    # one line for the reason, with its count (not one per file and line: tests/conftest.py)
    lines = [ln for ln in out.splitlines() if ln.startswith("SKIPPED [") and ": real data: " in ln]
    assert len(lines) == 1 and re.match(r"SKIPPED \[(\d+)\] tests: ", lines[0]), lines[:5]
    assert int(re.match(r"SKIPPED \[(\d+)\]", lines[0]).group(1)) > 50, lines[0]
    return closing


def test_plain_clone_collects_and_skips_the_real_data_tests(tmp_path):
    repo = _plain_clone(tmp_path)
    assert not (tmp_path / "shared").exists()
    closing = _check(_pytest(repo, "-m", "realdata and not slow"), tmp_path)
    assert "deselected" in closing  # everything was collected, the rest deselected


@pytest.mark.slow
def test_plain_clone_fast_suite_is_green(tmp_path):
    repo = _plain_clone(tmp_path)
    _check(_pytest(repo, "-m", "not slow"), tmp_path)


def test_shared_refuses_a_test_not_marked_realdata():
    """``shared()`` fails an unmarked test (the marks stay complete, so ``-m realdata`` above
    selects every test that needs ../shared), also with ../shared present."""
    with pytest.raises(pytest.fail.Exception, match="is not marked realdata"):
        shared("data")


@pytest.mark.realdata
def test_shared_gives_the_path_to_a_marked_test():
    assert shared("data").is_dir()  # skips without ../shared


PROBE = '''
import os

import pytest

from helpers_common import SHARED, shared


def test_unmarked_reads_past_shared():
    try:  # a path built from SHARED, not shared(): found by the audit of the test's file opens
        (SHARED / "data" / "SOURCES.md").read_text()
    except OSError:
        pass


def test_unmarked_lists_past_shared():
    try:
        os.listdir(SHARED / "data")
    except OSError:
        pass


@pytest.mark.realdata
def test_marked_reads():
    shared("data").is_dir()
'''


def test_a_test_reading_shared_unmarked_fails(tmp_path):
    """A test that reads ../shared past :func:`shared` (a path built from ``SHARED``) without the
    marker fails too (tests/conftest.py audits file opens and listings under ../shared), with or
    without ../shared present; a marked one passes or skips."""
    (tmp_path / "test_probe.py").write_text(PROBE)
    res = _pytest(ROOT, "-c", str(ROOT / "pyproject.toml"), "--rootdir", str(ROOT), "-p", "conftest",
                  str(tmp_path / "test_probe.py"), "-rfs")
    out = res.stdout + res.stderr
    assert res.returncode == 1, out[-3000:]
    failed = set(re.findall(r"FAILED \S*::(test_\w+)", out))
    assert failed == {"test_unmarked_reads_past_shared", "test_unmarked_lists_past_shared"}, out[-3000:]
    assert any(f"reads {p}" in out for p in (SHARED.resolve(), SHARED.absolute())) and "is not marked realdata" in out
    assert "1 ran on real data" in out or "1 real-data skipped" in out, out[-3000:]
