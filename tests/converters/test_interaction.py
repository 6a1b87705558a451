"""INTERACTION track files + their Lanelet2 map -> recording: the dataset's own test files and
files written here in its layout."""

from __future__ import annotations

import warnings

import numpy as np
import pyproj
import pytest
from helpers_common import shared
from helpers_lanelet2 import ORIGIN, crossroads

import aveas_format
from aveas_format.converters import convert
from aveas_format.errors import FormatError

OPTS = {"start_time": "2019-05-01T10:00:00Z", "license": "BSD-3-Clause"}


@pytest.mark.realdata
def test_the_datasets_test_scenario():
    d = shared("data", "real", "lanelet2")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = convert("interaction", [d / "interaction__vehicle_tracks_000.csv"],
                      map_source=d / "interaction__TestScenarioForScripts.osm", options=OPTS)
    assert any("states no uncertainty" in str(w.message) for w in caught)
    p = rec.participants.to_pydict()
    assert p["source_id"] == ["vehicle/1", "vehicle/2"] and p["class"] == ["car", "car"]
    s = rec.states.to_pandas()
    assert len(s) == 170 and (s.lane_id.fillna(0) != 0).mean() >= 0.98
    # lon/lat where the dataset puts them: x/y are UTM zone 31 minus UTM(0, 0)
    fwd = pyproj.Transformer.from_crs("EPSG:4326", "+proj=utm +zone=31 +datum=WGS84", always_xy=True)
    inv = pyproj.Transformer.from_crs("+proj=utm +zone=31 +datum=WGS84", "EPSG:4326", always_xy=True)
    e0, n0 = fwd.transform(0.0, 0.0)
    lon, lat = inv.transform(s.x.to_numpy() + e0, s.y.to_numpy() + n0)
    np.testing.assert_allclose(s.lon, lon, atol=1e-10)
    np.testing.assert_allclose(s.lat, lat, atol=1e-10)
    # the one real inconsistency (track 2 drives towards -x with vx = +10) and nothing else
    rep = aveas_format.validate(rec)
    assert sorted({(f[0], f[1]) for f in rep.flatten(("code", "participant_id"))}) == [
        ("kinematics.heading_vs_motion", 1), ("map.wrong_way", 1)]


def _tracks(path, rows, pedestrian=False):
    cols = ["track_id", "frame_id", "timestamp_ms", "agent_type", "x", "y", "vx", "vy"]
    if not pedestrian:
        cols += ["psi_rad", "length", "width"]
    path.write_text(",".join(cols) + "\n" + "".join(",".join(str(v) for v in r) + "\n" for r in rows))
    return path


def test_vehicles_and_pedestrians_on_a_converted_crossroads(tmp_path):
    text, _ = crossroads()
    osm = tmp_path / "site.osm"
    osm.write_text(text)
    # the map's frame: a transverse Mercator at ORIGIN; the tracks in UTM minus UTM(ORIGIN)
    fwd = pyproj.Transformer.from_crs("EPSG:4326", "+proj=utm +zone=32 +datum=WGS84", always_xy=True)
    loc = pyproj.Transformer.from_crs(f"+proj=tmerc +lat_0={ORIGIN[0]} +lon_0={ORIGIN[1]} +ellps=WGS84", "EPSG:4326",
                                      always_xy=True)
    e0, n0 = fwd.transform(ORIGIN[1], ORIGIN[0])

    def utm(x, y):
        lon, lat = loc.transform(x, y)
        e, n = fwd.transform(lon, lat)
        return e - e0, n - n0

    rows = []
    for k in range(40):  # a car eastbound on the east arm's outgoing lane (y = -1.75)
        x, y = utm(20.0 + k * 1.0, -1.75)
        rows.append([7, k + 1, 100 * (k + 1), "car", x, y, 10.0, 0.0, 0.0, 4.5, 1.9])
    peds = []
    for k in range(20):
        x, y = utm(31.5, -5.0 + 0.5 * k)
        peds.append(["P1", k + 1, 100 * (k + 1), "pedestrian/bicycle", x, y, 0.0, 5.0])
    v = _tracks(tmp_path / "vehicle_tracks_001.csv", rows)
    p = _tracks(tmp_path / "pedestrian_tracks_001.csv", peds, pedestrian=True)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = convert("interaction", [v, p], map_source=osm,
                      options={**OPTS, "origin": ORIGIN})
    parts = rec.participants.to_pydict()
    assert parts["source_id"] == ["pedestrian/P1", "vehicle/7"]
    assert parts["class"] == ["pedestrian", "car"]
    pmf = parts["class_pmf"][0]
    assert pmf["pedestrian"] == pytest.approx(0.5) and pmf["bicycle"] == pytest.approx(0.5)
    assert sum(pmf.values()) == pytest.approx(1.0)
    s = rec.states.to_pandas()
    car = s[s.participant_id == 1]
    assert (car.lane_id != 0).all()
    ped = s[s.participant_id == 0]
    np.testing.assert_allclose(ped.heading, np.pi / 2, atol=1e-9)  # from the velocity
    np.testing.assert_allclose(car.lon.iloc[0], loc.transform(20.0, -1.75)[0], atol=1e-9)


def test_bad_rows_name_the_file_and_line(tmp_path):
    text, _ = crossroads()
    osm = tmp_path / "site.osm"
    osm.write_text(text)
    v = _tracks(tmp_path / "vehicle_tracks_002.csv", [[1, 1, 100, "car", 0, 0, 1, 0, 0, 4, 2],
                                                       [1, 2, 200, "spaceship", 1, 0, 1, 0, 0, 4, 2]])
    with pytest.raises(FormatError, match=r"vehicle_tracks_002.csv: line 3: agent_type 'spaceship'"):
        convert("interaction", [v], map_source=osm, options=OPTS)
    v.write_text("track_id,frame_id,timestamp_ms,agent_type,x,y,vx,vy,psi_rad,length,width\n1,1,100,car,abc,0,1,0,0,4,2\n")
    with pytest.raises(FormatError, match="line 2"):
        convert("interaction", [v], map_source=osm, options=OPTS)
