"""Every real OpenSCENARIO file under ../shared/data (esmini's, with its catalogs and maps): it
converts (every entity, no "not converted" warning), validates without errors (unless the file
itself is defective: then the finding is asserted), exports to OpenLABEL / OpenSCENARIO / OSI and
imports back with the same motion, and is plausible against the file (entity count, duration,
trajectory lengths, positions on the map, speeds)."""

from __future__ import annotations

import warnings

import numpy as np
import pyarrow.compute as pc
import pytest

import aveas_format
from aveas_format.converters.registry import convert
from aveas_format.mapref.offmap import OffMapWarning
from helpers_realdata import DATA, assert_same_motion, crs_for, real_files, round_trips

def _is_scenario(param) -> bool:
    """A scenario (a Storyboard), not a catalog file (a Catalog)."""
    path = param.values[0]
    return path is None or b"<Storyboard" in path.read_bytes()


XOSC = [p for p in real_files("real/**/*.xosc") if _is_scenario(p)]
ESMINI_MAPS = DATA / "real" / "esmini" / "resources" / "xodr"

#: what is known of a file (others get the general checks): entities, duration (s), the shortest
#: and longest path of a participant (m), the share of vehicle states on a road, the map to use
#: where the file names none, and the error findings of a file that is defective itself
EXPECT = {
    "lane-change_trajectory_wp.xosc": dict(entities=1, duration=8.0, paths=(110.0, 112.0)),
    # Ego drives its trajectory at 10 m/s; the pedestrian is synchronised to reach its point with it
    # (the scenario ends when Ego reaches its end point, the pedestrian has walked 21 m of 30)
    "pedestrian_traj_synch.xosc": dict(entities=2, duration=(10.4, 10.8), paths=(15.0, 115.0)),
    # "A totally unrealistic example" (its own comment): a clothoid of curvature -0.1 1/m driven
    # at 17.5 m/s (30 m/s² lateral) and a NURBS swinging 20 m sideways
    "trajectory-test.xosc": dict(entities=2, duration=29.2, paths=(400.0, 800.0), on_map=0.8,
                                 defects={"kinematics.acceleration"}),
    # esmini's unit test of trajectory headings has no map (RoadNetwork is empty): it runs on
    # straight_500m; its cars are placed 4 m apart across the road (some on border lanes, some
    # against the lane direction: warnings)
    "traj_use_cases.xosc": dict(entities=6, duration=10.0, paths=(25.0, 50.5), on_map=0.6,
                                map="straight_500m.xodr"),
}


def _convert(path):
    exp = EXPECT.get(path.name, {})
    map_path = ESMINI_MAPS / exp["map"] if "map" in exp else None
    from lxml import etree

    lf = etree.parse(str(path)).getroot().find("RoadNetwork/LogicFile")
    if map_path is None and lf is None:
        pytest.skip(f"{path.name} names no map and none is known for it")
    logic = map_path or (path.parent / lf.get("filepath"))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = convert("openscenario", [path], map_source=map_path, crs=crs_for(logic))
    assert not [w for w in caught if issubclass(w.category, OffMapWarning)]  # (none is off its map)
    assert not [w for w in caught if "BoundingBox states" in str(w.message)]  # (no size 0)
    # esmini writes OpenSCENARIO's right-handed frame (no "CARLA:" header): nothing mirrored
    assert rec.meta.extras["openscenario"]["handedness"]["frame"] == "right"
    return rec, [str(w.message) for w in caught if issubclass(w.category, UserWarning)
                 and "not converted" in str(w.message)]


@pytest.mark.parametrize("path", XOSC)
def test_converts_validates_and_is_plausible(path, shared_data, tmp_path):
    from lxml import etree

    exp = EXPECT.get(path.name, {})
    rec, not_converted = _convert(path)
    assert not_converted == []
    n_objects = len(etree.parse(str(path)).getroot().findall("Entities/ScenarioObject"))
    assert rec.participants.num_rows == exp.get("entities", n_objects) == n_objects
    assert rec.meta.duration_s > 0
    if "duration" in exp:
        lo, hi = exp["duration"] if isinstance(exp["duration"], tuple) else (exp["duration"],) * 2
        assert lo - 0.06 <= rec.meta.duration_s <= hi + 0.06
    report = aveas_format.validate(rec)
    errors = {r.code for r in report.results if r.count and r.severity.value == "error"}
    assert errors == exp.get("defects", set()), report.flatten(("code", "message"))
    s = rec.states
    pid = s["participant_id"].to_numpy()
    x, y = s["x"].to_numpy(), s["y"].to_numpy()
    lengths = [float(np.sum(np.hypot(np.diff(x[pid == q]), np.diff(y[pid == q]))))
               for q in np.unique(pid)]
    lo, hi = exp.get("paths", (0.0, 1e4))
    assert lo <= min(lengths) and max(lengths) <= hi, lengths
    # on the map: the vehicles drive on their roads
    cls = dict(zip(rec.participants["participant_id"].to_pylist(), rec.participants["class"].to_pylist()))
    veh = np.isin(pid, [q for q, c in cls.items() if c not in ("pedestrian", "animal")])
    on_map = float(np.mean(~pc.is_null(s["road_id"]).to_numpy(zero_copy_only=False)[veh]))
    assert on_map >= exp.get("on_map", 0.9)
    # speeds within what the class can do (the validator's limits: kinematics.speed has no error)
    assert "kinematics.speed" not in errors


@pytest.mark.parametrize("path", XOSC)
def test_exports_and_imports_back(path, shared_data, tmp_path):
    """OpenLABEL, OpenSCENARIO and OSI exports import back with the same motion, also where the
    map has no geoReference (the crs travels: OpenLABEL metadata, the OSI proj_string, the
    companion map's geoReference)."""
    rec, _ = _convert(path)
    for name, back in round_trips(rec, tmp_path).items():
        assert back.meta.crs == rec.meta.crs or back.map.header.geo_reference, name
        assert_same_motion(rec, back, tol_m=1e-3 if name != "openlabel" else 1e-2)
        assert pc.sum(pc.is_null(back.states["road_id"])).as_py() <= \
            pc.sum(pc.is_null(rec.states["road_id"])).as_py() + 2, name


@pytest.mark.parametrize("path", XOSC)
def test_validate_the_scenario_as_submitted(path, shared_data, capsys):
    """``aveas-format validate FILE.xosc`` (issue 22) on esmini's files: imported on the fly with
    the map and CRS the conversion takes; no entity left unconverted (no
    source.openscenario.entity_not_converted / no_bounding_box), no tool failure."""
    import json

    from lxml import etree

    from aveas_format.cli.app import app
    from aveas_format.cli.common import run

    exp = EXPECT.get(path.name, {})
    map_path = ESMINI_MAPS / exp["map"] if "map" in exp else None
    lf = etree.parse(str(path)).getroot().find("RoadNetwork/LogicFile")
    if map_path is None and lf is None:
        pytest.skip(f"{path.name} names no map and none is known for it")
    crs = crs_for(map_path or (path.parent / lf.get("filepath")))
    args = ["validate", str(path), "--format", "json", *(["--map", str(map_path)] if map_path else []),
            *(["--crs", crs] if crs else [])]
    code = run(app, args)
    rep = json.loads(capsys.readouterr().out)
    errors = [r for r in rep["results"] if r["severity"] == "error"]
    assert code == (1 if errors else 0) and rep["recording"] == str(path) and not rep["failures"]
    found = {r["code"] for r in rep["results"]}
    assert not found & {"source.openscenario.entity_not_converted",
                        "source.openscenario.no_bounding_box"}
    assert "source.openscenario.vertex_without_time" in rep["rules_run"]
