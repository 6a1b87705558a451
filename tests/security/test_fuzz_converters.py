"""Fuzzing the source readers: a mutated source file gives a clear library error or a recording,
never an unexpected exception (issue 11). Each test mutates a real or generated source."""

from __future__ import annotations

import json
import math
import os
import shutil
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings

from aveas_format.converters import convert
from aveas_format.errors import AveasError
from aveas_format.opendrive.builder import straight_highway

from helpers_common import realdata_fixture, shared
from helpers_fuzz import OPS, mutate

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
def test_sumo_fcd(tmp_path_factory, west_map, sumo_data, ops):
    src = tmp_path_factory.mktemp("s") / "fcd.xml"
    src.write_bytes(mutate((sumo_data / "fcd_cartesian_excerpt.xml").read_bytes(), ops))
    _clean("sumo-fcd", [src], map_source=west_map)


@realdata_fixture(scope="module")
def openlabel_example():
    """The AVEAS minimum OpenLABEL example and the esmini map it refers to (../shared)."""
    return (shared("data", "openlabel", "aveas__minimum_openlabel_example.json").read_bytes(),
            shared("data", "xodr", "esmini__e6mini.xodr"))


@SETTINGS
@given(ops=OPS)
def test_openlabel(tmp_path_factory, openlabel_example, ops):
    data, xodr = openlabel_example
    d = tmp_path_factory.mktemp("o")
    src = d / "labels.json"
    src.write_bytes(mutate(data, ops))
    shutil.copy(xodr, d / "map.xodr")
    _clean("openlabel", [src], map_source=d / "map.xodr")


@pytest.fixture(scope="module")
def xosc(tmp_path_factory):
    from aveas_format.converters import get_converter
    from helpers_common import small_recording

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
    from aveas_format.converters.common.tables import read_table

    d = tmp_path_factory.mktemp("c")
    src = d / "t.csv"
    src.write_bytes(mutate(b"time,id,x,y,heading\n0.0,1,1.5,2.5,0.1\n0.1,1,1.6,2.5,0.1\n"
                           b"0.0,2,5.0,-1.0,3.1\n", ops))
    try:
        read_table(src, required=("time", "id", "x", "y"), numeric=("time", "x", "y", "heading"))
    except AveasError:
        pass


# --- the remaining source readers: valid sources built by the converters' own test generators ---
# tests/converters is not on sys.path (pythonpath = tests): its generators are imported by module name.
sys.path.insert(0, str(Path(__file__).parents[1] / "converters"))

from hypothesis import strategies as st  # noqa: E402


def _fuzz_one(tmp_path_factory, sources: dict, which: int, ops) -> tuple[Path, list[Path]]:
    """Write the valid sources (name -> bytes) to a fresh folder, one of them mutated."""
    d = tmp_path_factory.mktemp("f")
    names = sorted(sources)
    target = names[which % len(names)]
    out = []
    for name in names:
        p = d / name
        p.write_bytes(mutate(sources[name], ops) if name == target else sources[name])
        out.append(p)
    return d, out


def _read_all(folder: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


def _map(tmp_path_factory, **kw) -> Path:
    p = tmp_path_factory.mktemp("fmap") / "map.xodr"
    p.write_text(straight_highway(**kw))
    return p


WHICH = st.integers(0, 10)


class _Quiet(tuple):
    """A fixture's sources, kept out of hypothesis' (huge) failure report."""

    def __repr__(self):
        return "<valid sources>"


@pytest.fixture(scope="module")
def highd_src(tmp_path_factory):
    import test_levelx as lx

    d = tmp_path_factory.mktemp("hd")
    lx.write_highd(d / "h", lx.highd_truth(30))
    return _Quiet((_read_all(d / "h"),))


@SETTINGS
@given(ops=OPS, which=WHICH)
def test_highd(tmp_path_factory, highd_src, ops, which):
    d, _ = _fuzz_one(tmp_path_factory, highd_src[0], which, ops)
    _clean("highd", [d])


@pytest.fixture(scope="module")
def ind_src(tmp_path_factory):
    import test_levelx as lx

    d = tmp_path_factory.mktemp("ind")
    lx.write_centre(d / "i", lx.ind_truth(30), exid=True)
    m = _map(tmp_path_factory, length=200.0, lanes_right=1, lanes_left=1, x0=-100.0, y0=0.0,
             geo_reference=lx.SITE_CRS)
    return _Quiet((_read_all(d / "i"), m))


@SETTINGS
@given(ops=OPS, which=WHICH, exid=st.booleans())
def test_ind_exid(tmp_path_factory, ind_src, ops, which, exid):
    src, m = ind_src
    d, _ = _fuzz_one(tmp_path_factory, src, which, ops)
    _clean("exid" if exid else "ind", [d], map_source=m)


@pytest.fixture(scope="module")
def rotated_src(tmp_path_factory):
    import test_rotated_boxes as rb

    d = tmp_path_factory.mktemp("rb")
    rb.write_tracks(d / "tracks.csv", rb.truth(20))
    rb.write_world_file(d / "ortho.tfw")
    (d / "ortho.prj").write_text(rb.SITE_CRS)
    m = _map(tmp_path_factory, length=400.0, lanes_right=2, lanes_left=2, x0=-200.0, y0=0.0,
             geo_reference=rb.SITE_CRS)
    return _Quiet((_read_all(d), m, rb.RATE))


@SETTINGS
@given(ops=OPS, which=WHICH)
def test_rotated_boxes(tmp_path_factory, rotated_src, ops, which):
    src, m, rate = rotated_src
    _, files = _fuzz_one(tmp_path_factory, src, which, ops)
    _clean("rotated-boxes", files, map_source=m, options={"frame_rate": rate, "image_size": [3000, 1500]})


@realdata_fixture(scope="module")
def ros2_src(tmp_path_factory):
    pytest.importorskip("mcap_ros2")
    import test_ros2_mcap as r

    msgs = []
    for i in range(5):
        t = i / r.RATE
        t_ns = r.T0 + int(round(t * 1e9))
        msgs.append(("/localization/kinematic_state", "nav_msgs/msg/Odometry", r.odometry(t_ns, t), t_ns))
        msgs.append(("/perception/object_recognition/tracking/objects",
                     "autoware_perception_msgs/msg/TrackedObjects", r.tracked(t_ns + 20_000_000, t), t_ns))
        msgs.append(("/radar/objects", "derived_object_msgs/msg/ObjectWithCovarianceArray",
                     r.derived(t_ns + 50_000_000, i), t_ns))
    p = r.write_mcap(tmp_path_factory.mktemp("mcap") / "scene.mcap", msgs)
    m = _map(tmp_path_factory, length=1000.0, lanes_right=3, x0=r.OFFSET[0], y0=r.OFFSET[1],
             hdg=r.YAW0, geo_reference=r.GEO)
    return _Quiet((p.read_bytes(), m, {"frame_offset": list(r.OFFSET), "ego_center_offset": 1.4,
                                        "partner": "t"}))


@SETTINGS
@given(ops=OPS)
def test_ros2_mcap(tmp_path_factory, ros2_src, ops):
    data, m, opts = ros2_src
    _, files = _fuzz_one(tmp_path_factory, {"scene.mcap": data}, 0, ops)
    _clean("ros2-mcap", files, map_source=m, options=opts)


@realdata_fixture(scope="module")
def lidar_src(tmp_path_factory):
    import test_infra_lidar as il

    src = {f"{k:06d}_s110_lidar_ouster_south.json": json.dumps(il.tum_frame(k)).encode() for k in range(4)}
    m = _map(tmp_path_factory, length=300.0, lanes_right=2, lanes_left=2, x0=-100.0, y0=0.0,
             geo_reference=il.GEO)
    return _Quiet((src, m))


@SETTINGS
@given(ops=OPS, which=WHICH)
def test_infra_lidar(tmp_path_factory, lidar_src, ops, which):
    src, m = lidar_src
    _, files = _fuzz_one(tmp_path_factory, src, which, ops)
    _clean("infra-lidar", files, map_source=m)


@pytest.fixture(scope="module")
def lwir_src(tmp_path_factory):
    import numpy as np
    import test_infra_lwir as iw

    xs = np.array([0.0, 0.0, 30.0, 30.0, 60.0, 60.0, 100.0, 100.0, 15.0, 80.0])
    ys = np.array([0.0, -10.5, 0.0, -10.5, 2.0, -10.5, 0.0, -10.5, -5.0, -3.0])
    u, v = iw.project(xs, ys)
    lm = "name,u,v,x,y\n" + "".join(f"L{i},{a:.6f},{b:.6f},{c},{d}\n"
                                    for i, (a, b, c, d) in enumerate(zip(u, v, xs, ys)))
    src = {"gt.txt": ("\n".join(iw.mot_lines()[:20]) + "\n").encode(), "landmarks.csv": lm.encode()}
    m = _map(tmp_path_factory, length=300.0, lanes_right=3, x0=-50.0, geo_reference=iw.GEO)
    return _Quiet((src, m))


@SETTINGS
@given(ops=OPS, which=WHICH)
def test_infra_lwir(tmp_path_factory, lwir_src, ops, which):
    src, m = lwir_src
    _, files = _fuzz_one(tmp_path_factory, src, which, ops)
    _clean("infra-lwir", files, map_source=m)


@pytest.fixture(scope="module")
def accident_src(tmp_path_factory):
    import test_accident as ac

    d = ac.write_case(tmp_path_factory.mktemp("acc") / "case")
    return _Quiet((_read_all(d),))


@SETTINGS
@given(ops=OPS, which=WHICH)
def test_accident(tmp_path_factory, accident_src, ops, which):
    d, _ = _fuzz_one(tmp_path_factory, accident_src[0], which, ops)
    _clean("accident", [d])


@pytest.fixture(scope="module")
def osi_src(tmp_path_factory):
    pytest.importorskip("betterosi")
    import test_osi as o

    t, objs = o.truth(8)
    p = o.write_osi(tmp_path_factory.mktemp("osi") / "run_gt.osi", o.messages(t, objs))
    m = _map(tmp_path_factory, length=600.0, lanes_right=2, lanes_left=1, geo_reference=o.GEO)
    return _Quiet((p.read_bytes(), m))


@SETTINGS
@given(ops=OPS)
def test_osi(tmp_path_factory, osi_src, ops):
    data, m = osi_src
    _, files = _fuzz_one(tmp_path_factory, {"run_gt.osi": data}, 0, ops)
    _clean("osi", files, map_source=m)


@pytest.fixture(scope="module")
def sim_src(tmp_path_factory):
    import test_driving_simulator as ds

    ego, lead = ds.truth(20)
    p = ds.write_log(tmp_path_factory.mktemp("sim") / "run.csv", ego, lead)
    m = _map(tmp_path_factory, length=1000.0, lanes_right=2, geo_reference=ds.GEO)
    return _Quiet((p.read_bytes(), m))


@SETTINGS
@given(ops=OPS)
def test_driving_simulator(tmp_path_factory, sim_src, ops):
    data, m = sim_src
    _, files = _fuzz_one(tmp_path_factory, {"run.csv": data}, 0, ops)
    _clean("driving-simulator", files, map_source=m, options={"reference_offset": -1.4})


# --- replays: the minimised inputs that once crashed these readers (each now a FormatError) ---

def _raises_format_error(name, files, **kw):
    from aveas_format.errors import FormatError

    with pytest.raises(FormatError) as e:
        convert(name, files, **kw)
    return str(e.value)


@pytest.mark.parametrize("ops", [[("flip", 231870299, 0)],   # zstandard.ZstdError (damaged chunk)
                                 [("dup", 0, 8)],            # MemoryError (huge record length)
                                 [("flip", 1170, 0)]])       # OverflowError (record length)
def test_replay_ros2_mcap_damaged_records(tmp_path_factory, ros2_src, ops):
    data, m, opts = ros2_src
    _, files = _fuzz_one(tmp_path_factory, {"scene.mcap": data}, 0, ops)
    try:
        convert("ros2-mcap", files, map_source=m, options=opts)
    except AveasError as e:
        assert "scene.mcap" in str(e)


def test_replay_rotated_boxes_unreadable_prj(tmp_path_factory, rotated_src):
    src, m, rate = rotated_src
    src = dict(src, **{"ortho.prj": b"+oj=tmerc +lat_0=4:.9 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84"})
    _, files = _fuzz_one(tmp_path_factory, src, 0, [])
    msg = _raises_format_error("rotated-boxes", files, map_source=m, options={"frame_rate": rate})
    assert "ortho.prj" in msg and "unreadable CRS" in msg


def test_replay_infra_lwir_non_utf8(tmp_path_factory, lwir_src):
    src, m = lwir_src
    src = dict(src, **{"gt.txt": b"\xb1" + src["gt.txt"][1:]})   # was: ArrowInvalid from a cast
    _, files = _fuzz_one(tmp_path_factory, src, 0, [])
    msg = _raises_format_error("infra-lwir", files, map_source=m)
    assert "gt.txt" in msg and "line 1" in msg and "not UTF-8" in msg, msg


def test_replay_driving_simulator_non_utf8(tmp_path_factory, sim_src):
    data, m = sim_src
    lines = data.split(b"\n")
    lines[4] = lines[4].replace(b'"car"', b'"c\xffr"')
    _, files = _fuzz_one(tmp_path_factory, {"run.csv": b"\n".join(lines)}, 0, [])
    msg = _raises_format_error("driving-simulator", files, map_source=m)
    assert "run.csv" in msg and "line 5" in msg and "not UTF-8" in msg, msg


def test_replay_accident_duplicate_header_column(tmp_path_factory, accident_src):
    src = dict(accident_src[0])
    head, rest = src["case.csv"].split(b"\n", 1)
    src["case.csv"] = head + b",position_tol_m\n" + rest.replace(b"\n", b",0.3\n", 1)  # was: KeyError
    d, _ = _fuzz_one(tmp_path_factory, src, 0, [])
    msg = _raises_format_error("accident", [d])
    assert "case.csv" in msg and "line 1" in msg and "more than once" in msg, msg


def test_replay_accident_empty_dynamics(tmp_path_factory, accident_src):
    src = dict(accident_src[0])
    src["dynamics.csv"] = src["dynamics.csv"].split(b"\n", 1)[0] + b"\n"   # was: ValueError (min)
    d, _ = _fuzz_one(tmp_path_factory, src, 0, [])
    msg = _raises_format_error("accident", [d])
    assert "dynamics.csv" in msg and "no rows" in msg, msg
