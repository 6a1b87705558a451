"""Fixtures shared by more than one test folder (helper functions live in tests/helpers_*.py; see
tests/README.md), and the bookkeeping of the real-data tests (``../shared``): the ``realdata``
marker applied at collection to every test that uses a :func:`helpers_common.realdata_fixture`,
and their count in pytest's closing line (``... 212 ran on real data in 180s``; on a plain clone
``... 212 real-data skipped (no ../shared) in 150s``)."""

from __future__ import annotations

import os
import sys

import pytest

import helpers_common
from helpers_common import REALDATA, REALDATA_FIXTURES, SHARED, realdata_fixture, shared, small_recording
from hypothesis import settings

# `make test` is a gate: its property tests draw the same examples on every run (derandomize);
# `make test-all` explores afresh each time (HYPOTHESIS_PROFILE=explore), where a new failing
# example becomes an @example of its test
settings.register_profile("gate", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "gate"))


def pytest_collection_modifyitems(items):
    for item in items:
        if REALDATA_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(REALDATA)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item):
    helpers_common.CURRENT_TEST[0] = item


# A test that reads ../shared without the marker, past shared() (a path built from SHARED, a
# helper's constant): Python's own file opens and directory listings under ../shared are audited
# while a test runs, and an unmarked test that made one fails (files read by C libraries such as
# pyarrow or libxml2 are not seen; the plain-clone run catches those).
# (the path as built and as resolved: ../shared may be a link to the data elsewhere)
_SHARED_PREFIXES = tuple({str(SHARED.absolute()) + os.sep, str(SHARED.resolve()) + os.sep})
_UNMARKED: dict[str, str] = {}


def _audit(event: str, args: tuple) -> None:
    if event not in ("open", "os.listdir", "os.scandir") or not args:
        return
    item = helpers_common.CURRENT_TEST[0]
    if item is None or item.nodeid in _UNMARKED or isinstance(args[0], int) or args[0] is None:
        return
    try:
        path = os.path.abspath(os.fsdecode(args[0]))
    except (TypeError, ValueError):
        return
    if path.startswith(_SHARED_PREFIXES) and item.get_closest_marker("realdata") is None:
        _UNMARKED[item.nodeid] = path


sys.addaudithook(_audit)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    report = (yield).get_result()
    if call.when == "teardown":
        helpers_common.CURRENT_TEST[0] = None
    path = _UNMARKED.pop(item.nodeid, None) if call.when == "call" else None
    if path and report.passed:
        report.outcome = "failed"
        report.longrepr = (f"{item.nodeid} reads {path} but is not marked realdata: add "
                           "@pytest.mark.realdata or take the data from a realdata_fixture")


def _fold_skips_by_reason(stats: dict) -> None:
    """One line per distinct skip reason in pytest's short summary (``-ra``), with its count:
    pytest folds skips by (file, line, reason), so one reason given by tests in 40 files (the
    real-data tests on a plain clone) would print 40 lines. Skips of one reason from several
    places are given their common folder as the place (``SKIPPED [212] tests: real data: ...``);
    a reason from one place keeps it."""
    by_reason: dict[str, list] = {}
    for rep in stats.get("skipped", ()):
        longrepr = getattr(rep, "longrepr", None)
        if isinstance(longrepr, tuple) and len(longrepr) == 3:
            by_reason.setdefault(str(longrepr[2]), []).append(rep)
    for reason, reps in by_reason.items():
        places = {(str(r.longrepr[0]), r.longrepr[1]) for r in reps}
        if len(places) > 1:
            common = os.path.commonpath([os.path.abspath(path) for path, _ in places])
            for r in reps:
                r.longrepr = (common, None, reason)


def pytest_terminal_summary(terminalreporter):
    """Put the real-data tests into the closing line: how many ran (passed or failed), or, without
    ``../shared``, how many were skipped for it (a few marked tests do not need the data in every
    case and run anyway: they are not counted as real-data runs then); fold the skip summary by
    reason (:func:`_fold_skips_by_reason`). pytest prints its short summary after this hook."""
    stats = terminalreporter.stats
    _fold_skips_by_reason(stats)
    ran: dict[str, object] = {}
    skipped: dict[str, object] = {}
    for key in ("passed", "failed", "error", "skipped"):
        for rep in stats.get(key, ()):
            if "realdata" not in getattr(rep, "keywords", {}):
                continue
            if key == "skipped":
                skipped.setdefault(rep.nodeid, rep)
            elif key != "error":
                ran.setdefault(rep.nodeid, rep)
    if not SHARED.is_dir():
        if skipped:
            stats["real-data skipped (no ../shared)"] = list(skipped.values())
    elif ran:
        stats["ran on real data"] = list(ran.values())


@pytest.fixture
def rec():
    return small_recording()


@pytest.fixture
def written(tmp_path, rec):
    """A small recording written in directory form."""
    return rec.write(tmp_path / "small.aveas")


@realdata_fixture(scope="session")
def conformance_path():
    """The independently written conformance recording of ../shared."""
    return shared("data", "conformance", "highway.aveas")


@realdata_fixture(scope="session")
def sumo_data():
    """The SUMO FCD excerpts of ../shared/data/sumo (written by SUMO's own tests)."""
    return shared("data", "sumo")


@pytest.fixture(scope="session")
def sumo():
    """The SUMO binary of the runner and fitter tests (tests/sim, tests/fit); skips without SUMO."""
    from aveas_format.sim import SumoNotFoundError, find_sumo

    try:
        return find_sumo("sumo")
    except SumoNotFoundError:
        pytest.skip('SUMO not installed (pip install "aveas-format[sim]")')
