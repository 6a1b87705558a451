"""Helpers of the OpenDRIVE tests: paths of the hand-made fixtures and of the real maps in shared/."""

from __future__ import annotations

import importlib.util
import os
from functools import lru_cache
from pathlib import Path

import pytest
from lxml import etree

from aveas_format.opendrive import RoadNetwork, load_map

from helpers_common import SHARED, shared

DATA = Path(__file__).resolve().parent / "opendrive" / "data"
#: names of the real maps in ../shared/data/xodr (none without ../shared)
REAL_MAPS = sorted(p.name for p in (SHARED / "data" / "xodr").glob("*.xodr"))
#: maps whose consecutive geometries meet to <= 1e-6 m in the file itself
CONTINUOUS_MAPS = {
    "esmini__e6mini.xodr",
    "esmini__fabriksgatan.xodr",
    "esmini__multi_intersections.xodr",
    "esmini__parking_demo.xodr",
    "esmini__velodrome.xodr",
}


def real_map(name: str) -> RoadNetwork:
    """A real map of ../shared/data/xodr, for a realdata test (skips without ../shared)."""
    return _load(shared("data", "xodr", name))


@lru_cache(maxsize=None)
def _load(path: Path) -> RoadNetwork:
    return load_map(path)


@lru_cache(maxsize=None)
def fixture_map(name: str) -> RoadNetwork:
    return load_map(DATA / name)


def xsd_16():
    """The official OpenDRIVE 1.6 XSD shipped by PyPI ``asam-qc-opendrive`` (skip without it)."""
    spec = importlib.util.find_spec("qc_opendrive")
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("asam-qc-opendrive (which ships the official XSD) is not installed")
    core = Path(next(iter(spec.submodule_search_locations))) / "schema" / "1.6.1" / "opendrive_16_core.xsd"
    if not core.exists():
        pytest.skip(f"no OpenDRIVE 1.6 XSD at {core}")
    return etree.XMLSchema(etree.parse(str(core)))


@lru_cache(maxsize=1)
def _xsd_18():
    import xmlschema

    spec = importlib.util.find_spec("qc_opendrive")
    core = Path(next(iter(spec.submodule_search_locations))) / "schema" / "1.8.0" / "OpenDRIVE_Core.xsd"
    return xmlschema.XMLSchema11(str(core))


def xsd_18_errors(text: str) -> list[str]:
    """Violations of the official OpenDRIVE 1.8 XSD (shipped by PyPI ``asam-qc-opendrive``; an
    XSD 1.1 schema, read with ``xmlschema`` as qc-opendrive does) by the map ``text``; skips
    without them."""
    spec = importlib.util.find_spec("qc_opendrive")
    if spec is None or not spec.submodule_search_locations or importlib.util.find_spec("xmlschema") is None:
        pytest.skip("asam-qc-opendrive (which ships the official XSD) or xmlschema is not installed")
    return [str(e).splitlines()[0] for e in _xsd_18().iter_errors(text)]


# --- ASAM qc-opendrive, in its own environment ------------------------------------------------------
QC_VERSION = "1.0.0"
#: where the checker's environment lives between runs (its pins, numpy < 2 and lxml < 6, clash with
#: the project's, so it never shares our environment)
QC_HOME = Path(os.environ.get("AVEAS_QC_OPENDRIVE_HOME",
                              Path.home() / ".cache" / "aveas-format" / f"qc-opendrive-{QC_VERSION}"))
_QC_CONFIG = """<?xml version="1.0" encoding="UTF-8"?>
<Config>
  <Param name="InputFile" value="{input}"/>
  <CheckerBundle application="xodrBundle"><Param name="resultFile" value="{result}"/></CheckerBundle>
</Config>
"""


def qc_opendrive_bin() -> Path:
    """The ``qc_opendrive`` program of PyPI ``asam-qc-opendrive`` in its own venv under
    :data:`QC_HOME`, created on first use (under a lock, for parallel test workers); skips the
    test with one reason when it cannot be installed (no network, no venv module)."""
    import fcntl
    import subprocess
    import sys

    exe = QC_HOME / "bin" / "qc_opendrive"
    done = QC_HOME / ".installed"
    if done.exists():
        return exe
    QC_HOME.parent.mkdir(parents=True, exist_ok=True)
    with open(QC_HOME.parent / f".{QC_HOME.name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            try:
                subprocess.run([sys.executable, "-m", "venv", "--clear", str(QC_HOME)], check=True,
                               capture_output=True, timeout=300)
                subprocess.run([str(QC_HOME / "bin" / "python"), "-m", "pip", "install", "-q",
                                f"asam-qc-opendrive=={QC_VERSION}"], check=True, capture_output=True,
                               timeout=900)
            except (subprocess.SubprocessError, OSError) as e:
                detail = getattr(e, "stderr", b"") or str(e).encode()
                pytest.skip(f"ASAM qc-opendrive {QC_VERSION} cannot be installed in its own venv "
                            f"({QC_HOME}): {detail.decode(errors='replace').strip()[-300:]}")
            done.write_text(QC_VERSION)
    return exe


def qc_opendrive(path: Path) -> dict:
    """Run ASAM qc-opendrive on the map at ``path``: ``{"applicable": [checker ids that ran],
    "skipped": [...], "errors": [checkers with an internal error], "issues": [(checker id,
    description, xpath)]}`` read from its result file."""
    import subprocess

    exe = qc_opendrive_bin()
    path = Path(path).resolve()
    result = path.with_name(path.name + ".xqar")
    config = path.with_name(path.name + ".qc.xml")
    config.write_text(_QC_CONFIG.format(input=path, result=result), encoding="utf-8")
    run = subprocess.run([str(exe), "-c", str(config)], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    out: dict = {"applicable": [], "skipped": [], "errors": [], "issues": []}
    for c in etree.parse(str(result)).getroot().iter("Checker"):
        cid, status = c.get("checkerId"), c.get("status")
        out["applicable" if status == "completed" else "skipped" if status == "skipped" else "errors"].append(cid)
        for issue in c.iter("Issue"):
            xpaths = [loc.get("xpath") for loc in issue.iter("XMLLocation")]
            out["issues"].append((cid, issue.get("description"), xpaths[:1]))
    return out
