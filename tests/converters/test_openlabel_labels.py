"""Which OpenLABEL objects become participants (issue 42, points 7-8): objects without a 3D state
(2D image labels only) and static infrastructure stay out, each with one summary warning; the
vocabularies of the public OpenLABEL datasets (rail: OSDaR23/26; TUM Traffic, KITTI, nuScenes) map
to the 13 classes. On a small rail-like file written here with known truth, and on the real files
of ../shared (tests/realdata/test_openlabel.py)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert
from aveas_format.converters.labels import (IGNORE, NOT_ROAD_USER, ROAD_USER, is_infrastructure, label_kind,
                                            refine)
from aveas_format.opendrive.builder import straight_highway


GEO = "+proj=tmerc +lat_0=52.0 +lon_0=10.0 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
RATE, NF, T0 = 10.0, 30, 1_680_000_000.0
#: the movers: uid -> (type, x0, y, vx, (l, w, h)) and the class they must get
MOVERS = {"t1": ("train", -80.0, 5.25, 10.0, (60.0, 3.0, 4.0), "railvehicle"),
          "rv": ("road_vehicle", -40.0, -1.75, 8.0, (4.5, 1.8, 1.5), "car"),
          "lorry": ("road_vehicle", -70.0, -5.25, 6.0, (9.0, 2.5, 3.2), "truck"),  # (its boxes: type truck)
          "p1": ("person", 0.0, -5.0, 1.4, (0.5, 0.5, 1.8), "pedestrian")}
#: static infrastructure with label jitter: uid -> (type, x, y, (l, w, h))
STATIC = {"cp1": ("catenary_pole", 10.0, 9.0, (0.4, 0.4, 8.0)), "cp2": ("catenary_pole", 60.0, 9.0, (0.4, 0.4, 8.0)),
          "sw": ("switch", 30.0, 5.25, (20.0, 3.0, 0.3)), "bs": ("buffer_stop", 120.0, 5.25, (1.0, 3.0, 1.2)),
          "sg": ("signal", 80.0, 9.0, (0.5, 0.5, 6.0)), "sp": ("signal_pole", 80.0, 9.5, (0.3, 0.3, 5.0))}


def cuboid(x, y, yaw, size):
    l, w, h = size
    return {"name": "box", "val": [x, y, h / 2, 0.0, 0.0, float(np.sin(yaw / 2)), float(np.cos(yaw / 2)), l, w, h]}


def rail_doc(seed: int = 3) -> dict:
    """A rail scene in the OSDaR23 vocabulary: four movers (a road vehicle of type truck), six pieces of static infrastructure
    whose labels jitter by 5 cm a frame, a crowd, a track with a poly3d only, a car with 2D boxes
    only and a person with a static poly2d only."""
    rng = np.random.default_rng(seed)
    objects = {u: {"name": u, "type": v[0]} for u, v in {**MOVERS, **STATIC}.items()}
    objects.update({"cr": {"name": "cr", "type": "crowd"}, "tr": {"name": "tr", "type": "track"},
                    "img": {"name": "img", "type": "car"},
                    "img2": {"name": "img2", "type": "person",
                             "object_data": {"poly2d": [{"name": "outline", "val": [1, 2, 3, 4, 5, 6],
                                                         "mode": "MODE_POLY2D_ABSOLUTE", "closed": True}]}}})
    frames = {}
    for k in range(NF):
        t = k / RATE
        objs = {u: {"object_data": {"cuboid": [cuboid(x0 + vx * t, y, 0.0, size)]}}
                for u, (_, x0, y, vx, size, _) in MOVERS.items()}
        # OSDaR's layout: the annotation's attributes, the road vehicle's type among them
        objs["lorry"]["object_data"]["cuboid"][0]["attributes"] = {
            "text": [{"name": "occlusion", "val": "0-25 %"}, {"name": "type", "val": "truck"}],
            "boolean": [{"name": "isTruncated", "val": False}]}
        for u, (_, x, y, size) in STATIC.items():
            jx, jy, jyaw = rng.normal(0, 0.05, 3)
            objs[u] = {"object_data": {"cuboid": [cuboid(x + jx, y + jy, 0.2 * jyaw, size)]}}
        objs["cr"] = {"object_data": {"cuboid": [cuboid(-10.0, -9.0, 0.0, (5.0, 5.0, 1.8))]}}
        objs["tr"] = {"object_data": {"poly3d": [{"name": "rail", "val": [0, 0, 0, 100, 0, 0], "closed": False}]}}
        objs["img"] = {"object_data": {"bbox": [{"name": "2d", "val": [300 + k, 200, 40, 30]}]}}
        frames[str(k)] = {"frame_properties": {"timestamp": T0 + t}, "objects": objs}
    return {"openlabel": {"metadata": {"schema_version": "1.0.0"}, "objects": objects, "frames": frames}}


@pytest.fixture
def rail(tmp_path):
    p = tmp_path / "rail.json"
    p.write_text(json.dumps(rail_doc()))
    m = tmp_path / "site.xodr"
    m.write_text(straight_highway(length=300.0, lanes_right=2, lanes_left=3, x0=-120.0, geo_reference=GEO))
    return p, m


def _run(path, map_path, **opts):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        rec = convert("openlabel", [path], map_source=map_path,
                      options={"partner": "t", "license": "CC0-1.0", **opts})
    return rec, [str(x.message) for x in w]


def test_rail_scene_imports_the_movers_with_their_classes(rail):
    rec, notes = _run(*rail)
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == list(MOVERS)
    assert p.column("class").to_pylist() == [v[5] for v in MOVERS.values()]
    assert p.column("length").to_pylist() == pytest.approx([v[4][0] for v in MOVERS.values()])
    pid, t, x = (s.column(c).to_numpy() for c in ("participant_id", "time", "x"))
    for i, (_, x0, y, vx, _, _) in enumerate(MOVERS.values()):
        sel = pid == i
        assert t[sel] == pytest.approx(np.arange(NF) / RATE)
        assert x[sel] == pytest.approx(x0 + vx * t[sel], abs=1e-6)
        assert s.column("y").to_numpy()[sel] == pytest.approx(y, abs=1e-6)
        assert np.cos(s.column("heading").to_numpy()[sel]) == pytest.approx(1.0)  # (cuboid yaw 0)
    # one note for the objects that are no participant by their type, naming the infrastructure
    skipped = [n for n in notes if "skipped" in n]
    assert len(skipped) == 1, notes
    assert ("skipped 8 objects: 2 catenary_pole, 1 buffer_stop" in skipped[0] or
            "skipped 8 objects: 1 buffer_stop, 2 catenary_pole" in skipped[0]), skipped[0]
    assert "(static infrastructure: the map's, no participant)" in skipped[0]
    assert "1 crowd (ignore-type label" in skipped[0] and "1 track" in skipped[0]
    # one note for those without a 3D state: how many, what they have, the first
    no3d = [n for n in notes if "no 3D state" in n]
    assert len(no3d) == 1, notes
    assert "2 object(s) have no 3D state" in no3d[0]
    assert "1 with bbox" in no3d[0] and "1 with poly2d" in no3d[0] and "the first: 'img'" in no3d[0]
    # the infrastructure's label jitter is no motion of anything in the recording
    rep = aveas_format.validate(rec)
    assert not {c for c in rep.codes if c.startswith("kinematics.")}, rep.codes


def test_keep_non_road_users_keeps_the_infrastructure_as_other(rail):
    """The option keeps its meaning: objects that are no road user are imported (class other);
    ignore types and objects without a 3D state never are."""
    rec, notes = _run(*rail, keep_non_road_users=True)
    src = rec.participants.column("source_id").to_pylist()
    cls = dict(zip(src, rec.participants.column("class").to_pylist()))
    assert set(src) == set(MOVERS) | set(STATIC)  # (the track has no cuboid: no 3D state)
    assert {cls[u] for u in STATIC} == {"other"}
    assert "cr" not in src and "img" not in src  # ignore types and 2D-only: never
    heads = sorted(n.split(": OpenLABEL: ")[1] for n in notes)
    assert len(heads) == 2 and heads[0].startswith("3 object(s) have no 3D state"), notes
    assert heads[1].startswith("skipped 1 objects: 1 crowd (ignore-type label"), notes


def test_only_2d_labels_is_an_error_that_says_what_the_objects_have(tmp_path):
    doc = rail_doc()
    ol = doc["openlabel"]
    for fr in ol["frames"].values():
        fr["objects"] = {u: o for u, o in fr["objects"].items() if u in ("img", "tr")}
    ol["objects"] = {u: o for u, o in ol["objects"].items() if u in ("img", "img2")}
    p = tmp_path / "only2d.json"
    p.write_text(json.dumps(doc))
    m = tmp_path / "m.xodr"
    m.write_text(straight_highway(length=300.0, x0=-120.0, geo_reference=GEO))
    with pytest.raises(aveas_format.FormatError, match=r"3 objects carry labels without a cuboid only \(bbox, poly2d, poly3d\)"):
        convert("openlabel", [p], map_source=m)


#: the vocabularies of public OpenLABEL datasets: name -> (class, kind), from each dataset's documentation
VOCABULARIES = {
    # OSDaR23 (DB InfraGO's ontology; OSDaR26 adds wagon, scooter, pram, personal_item)
    "person": ("pedestrian", ROAD_USER), "train": ("railvehicle", ROAD_USER), "wagons": ("railvehicle", ROAD_USER),
    "wagon": ("railvehicle", ROAD_USER), "road_vehicle": ("car", ROAD_USER), "bicycle": ("bicycle", ROAD_USER),
    "motorcycle": ("motorcycle", ROAD_USER), "animal": ("animal", ROAD_USER),
    "wheelchair": ("mobility_device", ROAD_USER), "scooter": ("mobility_device", ROAD_USER),
    "pram": ("pushable_pullable", ROAD_USER),
    "crowd": ("other", IGNORE), "group_of_bicycles": ("other", IGNORE), "group_of_animals": ("other", IGNORE),
    "ignore_tracks": ("other", IGNORE),
    "drag_shoe": ("other", NOT_ROAD_USER), "personal_item": ("other", NOT_ROAD_USER),
    "flame": ("other", NOT_ROAD_USER), "smoke": ("other", NOT_ROAD_USER),
    **{n: ("other", NOT_ROAD_USER) for n in ("track", "transition", "switch", "catenary_pole", "signal_pole",
                                             "signal", "signal_bridge", "buffer_stop")},
    # TUM Traffic (A9, TUMTraf Intersection / V2X)
    "CAR": ("car", ROAD_USER), "TRUCK": ("truck", ROAD_USER), "TRAILER": ("trailer", ROAD_USER),
    "VAN": ("van", ROAD_USER), "BUS": ("bus", ROAD_USER), "PEDESTRIAN": ("pedestrian", ROAD_USER),
    "EMERGENCY_VEHICLE": ("car", ROAD_USER), "OTHER": ("other", ROAD_USER),
    # KITTI (VCD's OpenLABEL of KITTI tracking)
    "Van": ("van", ROAD_USER), "Cyclist": ("bicycle", ROAD_USER), "Tram": ("railvehicle", ROAD_USER),
    "Misc": ("other", ROAD_USER), "Person_sitting": ("pedestrian", NOT_ROAD_USER), "DontCare": ("other", IGNORE),
    # nuScenes (and lidarseg's surfaces and structures)
    "vehicle.bus.bendy": ("bus", ROAD_USER), "vehicle.construction": ("truck", ROAD_USER),
    "vehicle.emergency.ambulance": ("van", ROAD_USER), "human.pedestrian.police_officer": ("pedestrian", ROAD_USER),
    "human.pedestrian.stroller": ("pushable_pullable", ROAD_USER),
    "movable_object.pushable_pullable": ("pushable_pullable", ROAD_USER),
    "movable_object.trafficcone": ("other", NOT_ROAD_USER), "static_object.bicycle_rack": ("other", NOT_ROAD_USER),
    "static.manmade": ("other", NOT_ROAD_USER), "flat.driveable_surface": ("other", NOT_ROAD_USER),
    "noise": ("other", IGNORE),
}


@pytest.mark.parametrize("name", list(VOCABULARIES))
def test_dataset_vocabularies(name):
    assert label_kind(name) == VOCABULARIES[name]


@pytest.mark.parametrize("name,subtype,cls", [
    ("road_vehicle", "truck", "truck"), ("road_vehicle", "bus", "bus"), ("road_vehicle", "van", "van"),
    ("road_vehicle", "constructionVehicle", "truck"), ("road_vehicle", "trailer", "trailer"),
    ("road_vehicle", "other", "car"), ("road_vehicle", "unknown", "car"), ("road_vehicle", None, "car"),
    ("train", "locomotive", "railvehicle"), ("person", "worker", "pedestrian"),
    ("road_vehicle", "catenary_pole", "car"),  # (a subtype that is no road user names no class)
])
def test_a_generic_label_takes_the_class_of_its_subtype(name, subtype, cls):
    assert refine(name, subtype) == cls


def test_static_infrastructure_is_named_apart():
    assert all(is_infrastructure(n) for n in ("catenary_pole", "Switch", "buffer-stop", "signal_bridge",
                                              "traffic_light"))
    assert not any(is_infrastructure(n) for n in ("train", "road_vehicle", "drag_shoe", "barrier", "person"))
