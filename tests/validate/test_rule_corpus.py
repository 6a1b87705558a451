"""The corpus of broken recordings: one per rule, each caught by exactly the intended rule.

Every case mutates the clean recording of the fixture factory (``helpers_validate``) in one way and
states, as data, what the report must contain: the set of codes with findings is exactly the intended
one, and its first finding is at the expected (row, participant_id). The clean recording itself has
no finding at all (the passing fixture of every rule).
"""

from __future__ import annotations

import re
import sys
import types

import numpy as np
import pyarrow as pa
import pytest
import shapely

import aveas_format
import helpers_validate as vf
from aveas_format.validate import load_rules

# --- participants --------------------------------------------------------------------------------


def c_class_pmf_argmax(sc):
    sc["participants"]["class_pmf"][1] = np.eye(13, dtype=np.float32)[11]  # van, PMF says truck
    return vf.build(sc)


def c_size_implausible(sc):
    sc["participants"]["length"][0] = 9.0  # a 9 m car
    return vf.build(sc)


def c_size_std_missing(sc):
    sc["participants"]["width_std"] = np.array([0.1, 0.1, np.nan, 0.1])
    return vf.build(sc)


def c_attached_to_unknown(sc):
    sc["participants"]["attached_to"] = pa.array([None, None, 99, None], pa.int64())
    return vf.build(sc)


def c_without_states(sc):
    p = sc["participants"]
    for k in p:
        v = p[k]
        p[k] = np.concatenate([v, v[:1]]) if isinstance(v, np.ndarray) else list(v) + list(v[:1])
    p["participant_id"][-1] = 4
    return vf.build(sc)


def c_unknown_in_states(sc):
    sc["tracks"].append(vf.track(500.0, -2, 20.0, steps=10))
    sc["track_ids"] = [0, 1, 2, 3, 7]
    return vf.build(sc)


def c_unknown_reference(sc):
    sc["events"] = {"event_id": np.array([0], np.int64), "kind": ["following"],
                    "time_start": np.array([1.0]), "time_end": np.array([2.0]),
                    "participant_ids": pa.array([[0, 42]], pa.list_(pa.int64())),
                    "origin": ["annotated"]}
    return vf.build(sc)


# --- time ----------------------------------------------------------------------------------------


def c_out_of_range(sc):
    sc["meta"]["duration_s"] = 5.9  # the last sample (5.96 s) of each participant is later
    return vf.build(sc)


def c_not_increasing(sc):
    tr = sc["tracks"][0]
    for k in tr:  # a second sample 0.5 µs after the first, on the same trajectory
        v = tr[k]
        extra = v[0] + (tr["vx"][0] * 5e-7 if k == "x" else 5e-7 if k == "time" else 0.0)
        tr[k] = np.insert(v, 1, extra)
    return vf.build(sc)


def c_nominal_rate_low(sc):
    sc["meta"]["nominal_rate_hz"] = 8.0
    return vf.build(sc)


def c_rate_below_nominal(sc):
    tr = sc["tracks"][2]
    for k in tr:
        tr[k] = tr[k][::2]  # 12.5 Hz
    return vf.build(sc)


def c_gap(sc):
    tr = sc["tracks"][1]
    keep = (tr["time"] < 2.0) | (tr["time"] > 3.0)
    for k in tr:
        tr[k] = tr[k][keep]
    return vf.build(sc)


def c_interpolated_share(sc):
    n = sum(len(t["time"]) for t in sc["tracks"])
    flag = np.zeros(n, bool)
    flag[3 * vf.STEPS:] = True  # participant 3 entirely interpolated
    sc["extra_states"]["interpolated"] = flag
    return vf.build(sc)


def c_interval_order(sc):
    sc["events"] = {"event_id": np.array([0], np.int64), "kind": ["following"],
                    "time_start": np.array([3.0]), "time_end": np.array([2.0]),
                    "participant_ids": pa.array([[0, 2]], pa.list_(pa.int64())),
                    "origin": ["annotated"]}
    return vf.build(sc)


# --- kinematics ----------------------------------------------------------------------------------


def c_speed(sc):
    sc["tracks"][3] = vf.track(150.0, -3, 90.0)  # a car at 324 km/h, consistently
    return vf.build(sc)


def c_acceleration(sc):
    t = np.arange(vf.STEPS) / vf.RATE
    a = -18.0 * np.sin(np.pi * np.clip(t - 1.0, 0, 2) / 2.0) ** 2  # smooth, peak -18 m/s²
    v = 33.0 + np.r_[0, np.cumsum(0.5 * (a[1:] + a[:-1]) / vf.RATE)]
    sc["tracks"][3] = vf.track(150.0, -3, v)
    return vf.build(sc)


def c_jerk(sc):
    t = np.arange(vf.STEPS) / vf.RATE
    a = 9.0 * np.sign(np.sin(np.pi * (t + 1e-9)))  # +-9 m/s² every second: within accel bounds
    v = 33.0 + np.r_[0, np.cumsum(0.5 * (a[1:] + a[:-1]) / vf.RATE)]
    sc["tracks"][3] = vf.track(150.0, -3, v)
    n = sum(len(t["time"]) for t in sc["tracks"])
    sc["std"]["vx_std"] = sc["std"]["vy_std"] = np.full(n, 0.05)  # a precise velocity sensor
    return vf.build(sc)


def c_yaw_rate(sc):
    n = sum(len(t["time"]) for t in sc["tracks"])
    yr = np.zeros(n)
    yr[:vf.STEPS] = 3.0  # the yaw_rate column of car 0 says 3 rad/s
    sc["extra_states"]["yaw_rate"] = yr
    return vf.build(sc)


def c_heading_vs_motion(sc):
    sc["tracks"][0]["heading"][:] = 1.0  # a car driving sideways
    return vf.build(sc)


def c_position_jump(sc):
    sc["tracks"][0]["x"][75:] += 3.0  # the track teleports 3 m forward once
    return vf.build(sc)


def c_instant_lane_change(sc):
    sc["tracks"][0]["y"][75:] -= 3.5  # the car is in the next lane one step later, no lateral speed
    return vf.build(sc)


# --- uncertainty ---------------------------------------------------------------------------------


def c_std_missing(sc):
    del sc["std"]["heading_std"]
    return vf.build(sc)


def c_class_pmf_missing(sc):
    sc["pmf_null"] = np.array([False, False, True, False])
    return vf.build(sc)


def c_std_implausibly_large(sc):
    n = sum(len(t["time"]) for t in sc["tracks"])
    xs = np.full(n, 0.1)
    xs[vf.STEPS + 10] = 50.0  # a variance stored as std, once
    sc["std"]["x_std"] = xs
    return vf.build(sc)


def c_std_implausibly_small(sc):
    rng = np.random.default_rng(3)
    tr = sc["tracks"][1]
    tr["x"] = tr["x"] + rng.normal(0, 0.15, len(tr["x"]))
    n = sum(len(t["time"]) for t in sc["tracks"])
    xs = np.full(n, 0.1)
    xs[vf.STEPS:2 * vf.STEPS] = 0.01  # claims 1 cm while jittering by 15 cm
    sc["std"]["x_std"] = xs
    return vf.build(sc)


# --- geo -----------------------------------------------------------------------------------------


def c_crs_unparseable(sc):
    rec = vf.build(sc)
    rec.meta.crs = "+proj=nonsense +units=m"
    return rec


def c_crs_mismatch(sc):
    sc["meta"]["crs"] = vf.CRS.replace("+lon_0=8.35", "+lon_0=8.45")  # lon/lat follow this CRS
    return vf.build(sc)


def c_lonlat_mismatch(sc):
    rec = vf.build(sc)
    lat = vf.column(rec, "states", "lat")
    lat[5] += 1e-5  # 1.1 m north
    vf.set_column(rec, "states", "lat", lat)
    return rec


def c_location_outside_coverage(sc):
    rec = vf.build(sc)
    rec.meta.location = {"lon": rec.meta.location.lon + 0.1, "lat": rec.meta.location.lat}
    return rec


def c_state_outside_coverage(sc):
    sc["meta"]["coverage"] = "POLYGON ((0 -12, 300 -12, 300 2, 0 2, 0 -12))"
    return vf.build(sc)


# --- map -----------------------------------------------------------------------------------------


def c_unreadable(sc):
    rec = vf.build(sc)
    rec.map_source = b"<OpenDRIVE><header revMajor='1'"
    rec._map = None
    return rec


def c_opendrive_error(sc):
    sc["map"] = vf.MAP.replace("<link/>", '<link><successor elementType="road" elementId="99" '
                               'contactPoint="start"/></link>', 1)
    return vf.build(sc)


def c_opendrive_warning(sc):
    sc["map"] = vf.MAP.replace('length="1000.0" id="1"', 'length="1000.5" id="1"')
    return vf.build(sc)


def c_opendrive_info(sc):
    start = vf.MAP.index("<geoReference>")
    end = vf.MAP.index("</geoReference>") + len("</geoReference>")
    sc["map"] = vf.MAP[:start] + vf.MAP[end:]
    sc["meta"]["crs"] = vf.CRS
    return vf.build(sc)


def c_incomplete_road_coordinates(sc):
    rec = vf.build(sc)
    s = vf.column(rec, "states", "road_s")
    vf.set_column(rec, "states", "road_s", pa.array(s, mask=np.arange(len(s)) == 7))
    return rec


def c_unknown_road(sc):
    rec = vf.build(sc)
    r = rec.states.column("road_id").cast(pa.string()).to_pylist()
    r[9] = "42"
    vf.set_column(rec, "states", "road_id", pa.array(r).dictionary_encode())
    return rec


def c_unknown_lane(sc):
    rec = vf.build(sc)
    lane = vf.column(rec, "states", "lane_id")
    lane[11] = -4
    vf.set_column(rec, "states", "lane_id", pa.array(lane, pa.int16()))
    return rec


def c_road_position_mismatch(sc):
    rec = vf.build(sc)
    s = vf.column(rec, "states", "road_s")
    s[13] += 5.0
    vf.set_column(rec, "states", "road_s", s)
    return rec


def c_lane_mismatch(sc):
    rec = vf.build(sc)
    lane = vf.column(rec, "states", "lane_id")
    lane[15] = -2  # road_t says lane -1
    vf.set_column(rec, "states", "lane_id", pa.array(lane, pa.int16()))
    return rec


def c_lane_offset_mismatch(sc):
    rec = vf.build(sc)
    lo = vf.column(rec, "states", "lane_offset")
    lo[17] += 0.5
    vf.set_column(rec, "states", "lane_offset", lo)
    return rec


def c_off_drivable_lane(sc):
    i = vf.MAP.index('<lane id="-3" type="driving"')
    sc["map"] = vf.MAP[:i] + vf.MAP[i:].replace('type="driving"', 'type="shoulder"', 1)
    return vf.build(sc)


def c_wrong_way(sc):
    sc["tracks"][3] = vf.track(700.0, -3, -30.0)  # a ghost driver in the left lane
    return vf.build(sc)


# --- unobserved ----------------------------------------------------------------------------------


def c_invalid_geometry(sc):
    bowtie = shapely.Polygon([(900, -10), (950, 0), (950, -10), (900, 0), (900, -10)])
    sc["unobserved"]["geometry"] = [shapely.to_wkb(bowtie)]
    return vf.build(sc)


def c_time_order(sc):
    sc["unobserved"]["time_start"] = np.array([5.0])
    sc["unobserved"]["time_end"] = np.array([1.0])
    return vf.build(sc)


def c_outside_map(sc):
    sc["unobserved"]["geometry"] = [shapely.to_wkb(shapely.box(50000, 50000, 50100, 50100))]
    return vf.build(sc)


def c_state_inside(sc):
    sc["unobserved"]["geometry"] = [shapely.to_wkb(shapely.box(140.0, -3.5, 160.0, 0.0))]
    return vf.build(sc)


def c_table_missing(sc):
    sc["unobserved"] = None
    return vf.build(sc)


def c_coverage_missing(sc):
    sc["meta"]["coverage"] = None
    return vf.build(sc)


def c_coverage_invalid(sc):
    sc["meta"]["coverage"] = "POLYGON ((0 -12, 1000 2, 1000 -12, 0 2, 0 -12))"
    return vf.build(sc)


# --- interactions --------------------------------------------------------------------------------


def _add_participant(sc, cls, tr, length=4.5, width=1.8):
    p = sc["participants"]
    n = len(p["participant_id"])
    for k in p:
        v = p[k]
        p[k] = np.concatenate([v, v[:1]]) if isinstance(v, np.ndarray) else list(v) + list(v[:1])
    p["participant_id"][-1] = n
    p["class"][-1] = cls
    p["length"][-1], p["width"][-1] = length, width
    sc["tracks"].append(tr)


def c_overlap(sc):
    _add_participant(sc, "car", vf.track(70.0, -1, 35.0))  # drives through car 0
    return vf.build(sc)


def c_duplicate_track(sc):
    tr = vf.track(100.3, -1, 25.0)  # car 0 tracked twice, 0.3 m apart
    _add_participant(sc, "car", tr)
    return vf.build(sc)


# --- metadata ------------------------------------------------------------------------------------


def c_provenance_mismatch(sc):
    sc["participants"]["provenance"][1] = "simulated"
    sc["participants"]["role"][1] = "simulated_agent"
    return vf.build(sc)


def c_method_vs_provenance(sc):
    sc["meta"]["provenance"] = "simulated"
    sc["participants"]["provenance"] = ["simulated"] * 4
    sc["participants"]["role"] = ["simulated_agent"] * 4
    return vf.build(sc)


def c_method_vs_sensors(sc):
    sc["meta"]["acquisition"]["sensors"] = [{"id": "r", "kind": "radar"}]
    return vf.build(sc)


def c_should_field_missing(sc):
    del sc["meta"]["acquisition"]["platform"]
    return vf.build(sc)


def c_rights_unclear(sc):
    sc["meta"]["rights"]["license"] = "unknown"
    return vf.build(sc)


def c_partner_placeholder(sc):
    sc["meta"]["partner"] = "unknown"
    return vf.build(sc)


def c_start_time_implausible(sc):
    sc["meta"]["start_time"] = "1970-01-01T00:00:00Z"
    return vf.build(sc)


def c_derived_undocumented(sc):
    rec = vf.build(sc)
    rec.replace_tables({"derived/kinematics": vf.table_from_spec("derived/kinematics", 5)})
    return rec


# (case, code, (row, participant_id) of the first finding)
CASES = [
    (c_class_pmf_argmax, "participants.class_pmf_argmax", (1, 1)),
    (c_size_implausible, "participants.size_implausible", (0, 0)),
    (c_size_std_missing, "participants.size_std_missing", (2, 2)),
    (c_attached_to_unknown, "participants.attached_to_unknown", (2, 2)),
    (c_without_states, "participants.without_states", (4, 4)),
    (c_unknown_in_states, "participants.unknown_in_states", (600, 7)),
    (c_unknown_reference, "participants.unknown_reference", (0, 42)),
    (c_out_of_range, "time.out_of_range", (148, 0)),
    (c_not_increasing, "time.not_increasing", (1, 0)),
    (c_nominal_rate_low, "time.nominal_rate_low", (None, None)),
    (c_rate_below_nominal, "time.rate_below_nominal", (300, 2)),
    (c_gap, "time.gap", (200, 1)),
    (c_interpolated_share, "time.interpolated_share", (450, 3)),
    (c_interval_order, "time.interval_order", (0, None)),
    (c_speed, "kinematics.speed", (450, 3)),
    (c_acceleration, "kinematics.acceleration", None),
    (c_jerk, "kinematics.jerk", None),
    (c_yaw_rate, "kinematics.yaw_rate", (0, 0)),
    (c_heading_vs_motion, "kinematics.heading_vs_motion", (0, 0)),
    (c_position_jump, "kinematics.position_jump", (75, 0)),
    (c_instant_lane_change, "kinematics.instant_lane_change", (75, 0)),
    (c_std_missing, "uncertainty.std_missing", (0, 0)),
    (c_class_pmf_missing, "uncertainty.class_pmf_missing", (2, 2)),
    (c_std_implausibly_large, "uncertainty.std_implausibly_large", (160, 1)),
    (c_std_implausibly_small, "uncertainty.std_implausibly_small", (150, 1)),
    (c_crs_unparseable, "geo.crs_unparseable", (None, None)),
    (c_crs_mismatch, "geo.crs_mismatch", (None, None)),
    (c_lonlat_mismatch, "geo.lonlat_mismatch", (5, 0)),
    (c_location_outside_coverage, "geo.location_outside_coverage", (None, None)),
    (c_state_outside_coverage, "geo.state_outside_coverage", None),
    (c_unreadable, "map.unreadable", (None, None)),
    (c_opendrive_error, "map.opendrive_error", (None, None)),
    (c_opendrive_warning, "map.opendrive_warning", (None, None)),
    (c_opendrive_info, "map.opendrive_info", (None, None)),
    (c_incomplete_road_coordinates, "map.incomplete_road_coordinates", (7, 0)),
    (c_unknown_road, "map.unknown_road", (9, 0)),
    (c_unknown_lane, "map.unknown_lane", (11, 0)),
    (c_road_position_mismatch, "map.road_position_mismatch", (13, 0)),
    (c_lane_mismatch, "map.lane_mismatch", (15, 0)),
    (c_lane_offset_mismatch, "map.lane_offset_mismatch", (17, 0)),
    (c_off_drivable_lane, "map.off_drivable_lane", (450, 3)),
    (c_wrong_way, "map.wrong_way", (450, 3)),
    (c_invalid_geometry, "unobserved.invalid_geometry", (0, None)),
    (c_time_order, "unobserved.time_order", (0, None)),
    (c_outside_map, "unobserved.outside_map", (0, None)),
    (c_state_inside, "unobserved.state_inside", None),
    (c_table_missing, "unobserved.table_missing", (None, None)),
    (c_coverage_missing, "unobserved.coverage_missing", (None, None)),
    (c_coverage_invalid, "unobserved.coverage_invalid", (None, None)),
    (c_overlap, "interactions.overlap", None),
    (c_duplicate_track, "interactions.duplicate_track", (0, 0)),
    (c_provenance_mismatch, "metadata.provenance_mismatch", (None, None)),
    (c_method_vs_provenance, "metadata.method_vs_provenance", (None, None)),
    (c_method_vs_sensors, "metadata.method_vs_sensors", (None, None)),
    (c_should_field_missing, "metadata.should_field_missing", (None, None)),
    (c_rights_unclear, "metadata.rights_unclear", (None, None)),
    (c_partner_placeholder, "metadata.partner_placeholder", (None, None)),
    (c_start_time_implausible, "metadata.start_time_implausible", (None, None)),
    (c_derived_undocumented, "metadata.derived_undocumented", (None, None)),
]


def test_the_clean_recording_has_no_finding(clean):
    report = aveas_format.validate(clean)
    assert report.failures == []
    assert report.flatten(("code", "message")) == []


@pytest.mark.parametrize("case,code,where", CASES, ids=[c[1] for c in CASES])
def test_each_broken_recording_is_caught_by_exactly_its_rule(scene, case, code, where):
    rec = case(scene)
    report = aveas_format.validate(rec)
    assert report.failures == [], report.failures[0].traceback
    assert report.codes == {code}, report.flatten(("code", "row", "participant_id", "message"))
    first = report.results[0].sample[0]
    if where is not None:
        assert (first.location.row, first.location.participant_id) == where, first.message
    for f in report.findings():  # numbers in messages are rounded for people (no float noise)
        assert not re.search(r"\d\.\d{9,}|\de[-+]\d", f.message + f.location.text()), f.message
    sev = report.results[0].severity.value
    assert report.exit_code() == (1 if sev == "error" else 0)
    assert report.exit_code("warning") == (0 if sev == "info" else 1)


def test_derived_stale_asks_the_derivation_package(clean, monkeypatch):
    """metadata.derived_stale reports what ``derive.registry.stale_derived`` says (a list of names
    or a dict name -> reason), and nothing where the derivation package is missing."""
    assert "metadata.derived_stale" not in aveas_format.validate(clean).codes
    mod = types.ModuleType("aveas_format.derive.registry")
    mod.stale_derived = lambda rec: {"kinematics": "states changed since it was derived"}
    monkeypatch.setitem(sys.modules, "aveas_format.derive.registry", mod)
    report = aveas_format.validate(clean, select=["metadata.derived_stale"])
    assert report.flatten(("code", "table")) == [["metadata.derived_stale", "derived/kinematics"]]
    assert "states changed" in report.findings()[0].message
    mod.stale_derived = lambda rec: ["derived/kinematics", "events"]
    report = aveas_format.validate(clean, select=["metadata.derived_stale"])
    assert report.flatten(("code", "file")) == [["metadata.derived_stale",
                                                  "derived/kinematics.parquet"],
                                                 ["metadata.derived_stale", "events.parquet"]]
    monkeypatch.setitem(sys.modules, "aveas_format.derive.registry", None)  # import fails
    assert aveas_format.validate(clean, select=["metadata.derived_stale"]).codes == set()


def test_every_rule_has_a_failing_case():
    covered = {c[1] for c in CASES} | {"metadata.derived_stale", "map.mostly_off_road"}
    # source.* rules report an import's findings, not a recording's: their cases are in
    # test_validate_submission.py (one per code)
    semantic = {c for c in load_rules() if not c.startswith(("structure.", "zzz.", "source."))}
    assert semantic == covered


def test_overlap_is_exempt_for_accidents_and_attached_participants():
    """interactions.overlap: no finding where an accident event names both participants and covers
    the time, nor for a trailer attached_to its towing vehicle."""
    sc = vf.fresh()
    c_overlap(sc)
    sc["events"] = {"event_id": np.array([0], np.int64), "kind": ["accident"],
                    "time_start": np.array([0.0]), "time_end": np.array([5.96]),
                    "participant_ids": pa.array([[0, 4]], pa.list_(pa.int64())),
                    "origin": ["annotated"]}
    assert aveas_format.validate(vf.build(sc)).codes == set()
    sc = vf.fresh()
    c_overlap(sc)
    sc["participants"]["attached_to"] = pa.array([None, None, None, None, 0], pa.int64())
    assert aveas_format.validate(vf.build(sc), select=["interactions"]).codes == set()


# --- map.mostly_off_road: with map.off_drivable_lane by nature (each vehicle is off the map too) ---

def _moved(sc, transform):
    """The scene's states moved by ``transform(x, y) -> (x, y)`` (road coordinates recomputed)."""
    for tr in sc["tracks"]:
        tr["x"], tr["y"] = transform(np.asarray(tr["x"]), np.asarray(tr["y"]))
    return vf.build(sc)


@pytest.mark.parametrize("transform,cause", [
    (lambda x, y: (y, x), "with x and y swapped, 100% would be on a road"),
    (lambda x, y: (x * 100.0, y * 100.0), "read as centimetres, 100% would be on a road"),
    (lambda x, y: (x + 5000.0, y + 3000.0), "y mirrored): none puts the positions on the map"),
    (lambda x, y: (x, -y), "with y negated (a left-handed frame, as CARLA's), 100% would be on a road"),
])
def test_mostly_off_road_names_the_likely_cause(scene, transform, cause):
    """A recording whose vehicles are on no road (issue 18, point 7) is an error naming the likely
    causes, and the cheap ones are tried: swapped axes and units put the points back on the map."""
    rec = _moved(scene, transform)
    report = aveas_format.validate(rec, select=["map"])  # (geo and kinematics notice it too)
    assert report.codes == {"map.mostly_off_road", "map.off_drivable_lane"}, report.codes
    f = report.findings()[[r.code for r in report.results].index("map.mostly_off_road")]
    assert f.severity.value == "error" and cause in f.message, f.message
    # the threshold is configurable
    assert "map.mostly_off_road" not in aveas_format.validate(
        rec, config={"map": {"off_road_share": 1.0}}).codes


def test_mostly_off_road_counts_vehicles(scene):
    """Half the vehicles off the map is below the default threshold (more than half)."""
    n = len(scene["tracks"])
    for tr in scene["tracks"][: n // 2]:
        tr["y"] = np.asarray(tr["y"]) + 3000.0
    assert "map.mostly_off_road" not in aveas_format.validate(vf.build(scene)).codes
