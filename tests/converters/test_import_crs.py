"""The shared ``--crs`` (API ``crs=``, ``-O crs=``) walked over every registered importer: on a map
without ``<geoReference>`` the recording's CRS is the one given, and its lon/lat are the map-frame
positions projected through that CRS by pyproj (the external reference). Importers that build their
own map put it in the map's geoReference. Without it, where one is needed, the error suggests
``--crs``.

The inputs are the small ones each converter's own tests write (loaded from those modules)."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pyproj
import pytest

from aveas_format.converters import convert, load_converters
from aveas_format.errors import MissingCrsError
from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import straight_highway

pytestmark = pytest.mark.filterwarnings("ignore::aveas_format.converters.registry.UnstatedWarning")

#: a transverse Mercator at a site (not the default of any converter)
CRS = "+proj=tmerc +lat_0=50.78 +lon_0=6.08 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
HERE = Path(__file__).parent


def sibling(name: str):
    """The test module ``name`` of this folder (its input writers)."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


def plain_map(d: Path, **kw) -> Path:
    p = d / "plain.xodr"
    p.write_text(straight_highway(**{"length": 600.0, "lanes_right": 3, "lanes_left": 2, "x0": -200.0, **kw}))
    assert load_map(p.read_bytes()).header.geo_reference is None
    return p


def _accident(d):
    return [*sibling("test_accident").write_case(d / "case").iterdir()], None, {}


def _driving_simulator(d):
    m = sibling("test_driving_simulator")
    ego, lead = m.truth()
    return [m.write_log(d / "run.csv", ego, lead)], plain_map(d), {"reference_offset": -1.4}


def _highd(d):
    return [sibling("test_levelx").write_highd(d / "highd")[0]], None, {}


def _ind(d, exid=False):
    m = sibling("test_levelx")
    files = m.write_centre(d / "ind", m.ind_truth(), exid=exid)
    return files, plain_map(d, y0=-44.0, x0=-50.0, length=300.0, lanes_right=2), {}


def _infra_lidar(d):
    m = sibling("test_infra_lidar")
    files = []
    for k in range(5):
        p = d / f"{k:06d}_s110_lidar_ouster_south.json"
        p.write_text(json.dumps(m.tum_frame(k)))
        files.append(p)
    return files, plain_map(d), {}


def _infra_lwir(d):
    m = sibling("test_infra_lwir")
    mot = d / "gt.txt"
    mot.write_text("\n".join(m.mot_lines()) + "\n")
    lm = m.write_landmarks(d / "landmarks.csv")
    return [mot, lm], plain_map(d), {}


def _openlabel(d):
    """A generic file: cuboids in the root frame (the map's), no projection_string."""
    frames = {str(k): {"frame_properties": {"timestamp": 1.7e9 + 0.1 * k}, "objects": {
        "0": {"object_data": {"cuboid": [{"name": "box", "val": [-20 + 1.5 * k, -1.75, 0.75, 0, 0, 0, 1,
                                                                  4.5, 1.8, 1.5]}]}},
        "1": {"object_data": {"cuboid": [{"name": "box", "val": [30 - 1.2 * k, 1.75, 0.75, 0, 0, 1, 0,
                                                                  4.2, 1.8, 1.5]}]}}}} for k in range(10)}
    doc = {"openlabel": {"metadata": {"schema_version": "1.0.0"},
                         "objects": {"0": {"name": "a", "type": "car"}, "1": {"name": "b", "type": "van"}},
                         "frames": frames}}
    p = d / "plain.json"
    p.write_text(json.dumps(doc))
    return [p], plain_map(d), {}


def _openscenario(d):
    m = sibling("test_openscenario_import")
    p = m.xosc(d, m.ent("A"), m.teleport("A", '<WorldPosition x="10" y="-1.75" h="0"/>', 10.0),
               stop='<ConditionGroup><Condition name="end" delay="0" conditionEdge="rising"><ByValueCondition>'
                    '<SimulationTimeCondition value="2" rule="greaterThan"/></ByValueCondition></Condition>'
                    '</ConditionGroup>')
    return [p], plain_map(d), {}


def _osi(d):
    m = sibling("test_osi")
    t, objs = m.truth()
    return [m.write_osi(d / "run_gt.osi", m.messages(t, objs))], plain_map(d), {}


def _ros2_mcap(d):
    """The ego from NavSatFix (projected through the map frame's CRS: here the one given)."""
    m = sibling("test_ros2_mcap")
    path = m.write_mcap(d / "fix.mcap", m.navsatfix_messages(CRS))
    return [path], plain_map(d, x0=m.OFFSET[0], y0=m.OFFSET[1], hdg=m.YAW0, lanes_left=0, length=1000.0), \
        m._opts(ego_center_offset=0.0)


def _rotated_boxes(d):
    """``crs`` of this converter is its world file's CRS: without a map geoReference it is also
    the recording's."""
    m = sibling("test_rotated_boxes")
    _, inputs = m.centre_inputs(d)
    inputs = [p for p in inputs if p.suffix != ".prj"]
    return inputs, plain_map(d), {"frame_rate": m.RATE}


def _sumo_fcd(d):
    m = sibling("test_sumo_fcd")
    p = d / "fcd.xml"
    p.write_text(m._fcd([(0.5 * k, "a", 10.0 + 15.0 * 0.5 * k, -8.0, 90.0, 15.0, None) for k in range(20)]))
    return [p], plain_map(d), {}


BUILD = {
    "accident": _accident, "driving-simulator": _driving_simulator, "highd": _highd, "ind": _ind,
    "exid": lambda d: _ind(d, exid=True), "infra-lidar": _infra_lidar, "infra-lwir": _infra_lwir,
    "openlabel": _openlabel, "openscenario": _openscenario, "osi": _osi, "rotated-boxes": _rotated_boxes,
    "sumo-fcd": _sumo_fcd, "ros2-mcap": _ros2_mcap,
}
#: importers not walked, each with its reason
SKIP = {
    "interaction": "its map is a Lanelet2 OSM file in lon/lat: the converted map always has a "
                   "geoReference (no map without one to walk); a --crs must equal it",
}
#: importers whose inputs read ../shared
REAL = {"infra-lidar", "ros2-mcap"}  # (a real calibration; the ROS 2 message definitions)


def importers() -> list:
    names = sorted(c.name for c in load_converters().values() if c.direction == "import")
    return [pytest.param(n, marks=[pytest.mark.skip(reason=SKIP[n])] if n in SKIP else
                         [pytest.mark.realdata] if n in REAL else []) for n in names]


def test_every_importer_is_walked():
    names = {c.name for c in load_converters().values() if c.direction == "import"}
    assert names == set(BUILD) | set(SKIP), "a new importer: add its inputs to BUILD (or a reason to SKIP)"


@pytest.mark.parametrize("name", importers())
def test_crs_option_is_the_recordings_crs(name, tmp_path):
    inputs, map_path, opts = BUILD[name](tmp_path)
    rec = convert(name, inputs, map_source=map_path, options=opts, crs=CRS)
    assert rec.meta.crs == CRS
    if map_path is None:  # the importer built its map: the CRS is its geoReference
        assert rec.map.header.geo_reference == CRS
    s = rec.states
    assert s.num_rows > 0
    lon, lat = pyproj.Transformer.from_crs(pyproj.CRS(CRS), "EPSG:4326", always_xy=True).transform(
        s.column("x").to_numpy(), s.column("y").to_numpy())
    assert np.allclose(s.column("lon").to_numpy(), lon, atol=1e-9)
    assert np.allclose(s.column("lat").to_numpy(), lat, atol=1e-9)
    assert abs(float(np.mean(lat)) - 50.78) < 0.05 and abs(float(np.mean(lon)) - 6.08) < 0.05
    # the same through -O crs= (options)
    rec2 = convert(name, inputs, map_source=map_path, options={**opts, "crs": CRS})
    assert rec2.meta.crs == CRS


def test_openlabel_without_any_crs_suggests_the_option(tmp_path):
    inputs, map_path, _ = _openlabel(tmp_path)
    with pytest.raises(MissingCrsError) as e:
        convert("openlabel", inputs, map_source=map_path)
    msg = str(e.value)
    assert "--crs" in msg and "aveas-format convert --from openlabel" in msg
    assert msg.count("neither the map (<geoReference>) nor the file (metadata.projection_string)") == 1


def test_crs_that_differs_from_the_maps_geo_reference_is_refused(tmp_path):
    inputs, _, _ = _openlabel(tmp_path)
    geo = tmp_path / "geo.xodr"
    geo.write_text(straight_highway(length=600.0, x0=-200.0, lanes_left=2,
                                    geo_reference="+proj=tmerc +lat_0=48 +lon_0=11 +ellps=WGS84 +units=m"))
    from aveas_format.errors import FormatError

    with pytest.raises(FormatError, match="differs from the map's <geoReference>"):
        convert("openlabel", inputs, map_source=geo, crs=CRS)


def test_cli_crs_and_option_and_the_hint_without_them(tmp_path):
    """The issue's case on the command line: without a CRS the usage error (exit 2) shows the
    command with --crs; --crs and -O crs= both give the recording its CRS."""
    import subprocess

    import aveas_format

    inputs, map_path, _ = _openlabel(tmp_path)

    def cli(*args):
        return subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "openlabel", inputs[0],
                               "--map", map_path, *args], capture_output=True, text=True, timeout=300)

    res = cli("-o", tmp_path / "none.aveas")
    assert res.returncode == 2, res.stderr
    assert "--crs '+proj=tmerc" in res.stderr and "aveas-format convert --from openlabel" in res.stderr
    assert not (tmp_path / "none.aveas").exists()
    for name, args in (("a", ["--crs", CRS]), ("b", ["-O", f"crs={CRS}"])):
        res = cli(*args, "-o", tmp_path / f"{name}.aveas")
        assert res.returncode == 0, res.stderr
        assert aveas_format.open(tmp_path / f"{name}.aveas").meta.crs == CRS


@pytest.mark.realdata
def test_navsatfix_goes_through_the_crs_option(tmp_path):
    """ROS 2 NavSatFix on a map without geoReference: the lon/lat projected through --crs land on
    the ego's true map-frame track; without it the error suggests --crs."""
    m = sibling("test_ros2_mcap")
    inputs, map_path, opts = _ros2_mcap(tmp_path)
    rec = convert("ros2-mcap", inputs, map_source=map_path, options=opts, crs=CRS)
    s = rec.states
    e = s.column("participant_id").to_numpy() == 0
    t = s.column("time").to_numpy()[e]
    tx, ty = m.to_local(m.ego_x(t), np.full(e.sum(), m.EGO_Y))
    assert np.allclose(s.column("x").to_numpy()[e], tx, atol=1e-6)
    assert np.allclose(s.column("y").to_numpy()[e], ty, atol=1e-6)
    with pytest.raises(MissingCrsError, match="NavSatFix.*--crs"):
        convert("ros2-mcap", inputs, map_source=map_path, options=opts)
