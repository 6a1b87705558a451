"""Fuzzing the source readers: a mutated source file gives a clear library error or a recording,
never an unexpected exception (issue 11). Each test mutates a real or generated source."""

from __future__ import annotations

import math
import os
import shutil

import pytest
from hypothesis import HealthCheck, given, settings

from aveas_format.converters import convert
from aveas_format.errors import AveasError
from aveas_format.opendrive.builder import straight_highway

from aveas_testing import SHARED
from fuzzing import OPS, mutate

N = int(os.environ.get("AVEAS_FUZZ_EXAMPLES", "25"))
SETTINGS = settings(max_examples=N, deadline=None, derandomize=not os.environ.get("AVEAS_FUZZ_EXAMPLES"),
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _clean(name, files, **kw):
    try:
        convert(name, files, **kw)
    except AveasError:
        pass


@pytest.fixture(scope="module")
def west_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("fm") / "west.xodr"
    p.write_text(straight_highway(length=2000.0, lanes_right=1, x0=1600.0, y0=401.65 - 1.75,
                                  hdg=math.pi, geo_reference="+proj=tmerc +lat_0=48.8 +lon_0=11.1 "
                                  "+k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"))
    return p


@SETTINGS
@given(ops=OPS)
def test_sumo_fcd(tmp_path_factory, west_map, ops):
    src = tmp_path_factory.mktemp("s") / "fcd.xml"
    src.write_bytes(mutate((SHARED / "data" / "sumo" / "fcd_cartesian_excerpt.xml").read_bytes(), ops))
    _clean("sumo-fcd", [src], map_source=west_map)


@SETTINGS
@given(ops=OPS)
def test_openlabel(tmp_path_factory, ops):
    d = tmp_path_factory.mktemp("o")
    src = d / "labels.json"
    src.write_bytes(mutate((SHARED / "data" / "openlabel" / "aveas__minimum_openlabel_example.json")
                           .read_bytes(), ops))
    shutil.copy(SHARED / "data" / "xodr" / "esmini__e6mini.xodr", d / "map.xodr")
    _clean("openlabel", [src], map_source=d / "map.xodr")


@pytest.fixture(scope="module")
def xosc(tmp_path_factory):
    from aveas_format.converters import get_converter
    from aveas_testing import small_recording

    d = tmp_path_factory.mktemp("x")
    get_converter("openscenario", "export")(small_recording(n=2, steps=10), d / "s.xosc")
    return d


@SETTINGS
@given(ops=OPS)
def test_openscenario(tmp_path_factory, xosc, ops):
    d = tmp_path_factory.mktemp("xm")
    for f in xosc.iterdir():
        shutil.copy(f, d / f.name)
    (d / "s.xosc").write_bytes(mutate((xosc / "s.xosc").read_bytes(), ops))
    _clean("openscenario", [d / "s.xosc"])


@SETTINGS
@given(ops=OPS)
def test_csv_source(tmp_path_factory, ops):
    """The shared CSV reader under every CSV converter: a driving-simulator-style table."""
    from aveas_format.converters.common import read_table

    d = tmp_path_factory.mktemp("c")
    src = d / "t.csv"
    src.write_bytes(mutate(b"time,id,x,y,heading\n0.0,1,1.5,2.5,0.1\n0.1,1,1.6,2.5,0.1\n"
                           b"0.0,2,5.0,-1.0,3.1\n", ops))
    try:
        read_table(src, required=("time", "id", "x", "y"), numeric=("time", "x", "y", "heading"))
    except AveasError:
        pass
