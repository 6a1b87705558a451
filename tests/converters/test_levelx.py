"""levelX (highD, inD family, exiD) -> recording, on fixtures written in the datasets' exact CSV
layouts from an analytic truth; the converted centre, heading and velocity are compared with it."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyproj
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.converters.levelx import highd_map, shifted_crs, utm_crs_for
from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import straight_highway

RATE = 25.0
UPPER = [8.51, 12.59, 16.43]
LOWER = [21.00, 24.96, 28.74]

HIGHD_TRACKS = ["frame", "id", "x", "y", "width", "height", "xVelocity", "yVelocity", "xAcceleration",
                "yAcceleration", "frontSightDistance", "backSightDistance", "dhw", "thw", "ttc",
                "precedingXVelocity", "precedingId", "followingId", "leftPrecedingId",
                "leftAlongsideId", "leftFollowingId", "rightPrecedingId", "rightAlongsideId",
                "rightFollowingId", "laneId"]
HIGHD_META = ["id", "width", "height", "initialFrame", "finalFrame", "numFrames", "class",
              "drivingDirection", "traveledDistance", "minXVelocity", "maxXVelocity",
              "meanXVelocity", "minDHW", "minTHW", "minTTC", "numLaneChanges"]
HIGHD_REC = ["id", "frameRate", "locationId", "speedLimit", "month", "weekDay", "startTime",
             "duration", "totalDrivenDistance", "totalDrivenTime", "numVehicles", "numCars",
             "numTrucks", "upperLaneMarkings", "lowerLaneMarkings"]
IND_TRACKS = ["recordingId", "trackId", "frame", "trackLifetime", "xCenter", "yCenter", "heading",
              "width", "length", "xVelocity", "yVelocity", "xAcceleration", "yAcceleration",
              "lonVelocity", "latVelocity", "lonAcceleration", "latAcceleration"]
IND_META = ["recordingId", "trackId", "initialFrame", "finalFrame", "numFrames", "width", "length",
            "class"]
IND_REC = ["recordingId", "locationId", "frameRate", "speedLimit", "weekday", "startTime", "duration",
           "numTracks", "numVehicles", "numVRUs", "latLocation", "lonLocation", "xUtmOrigin",
           "yUtmOrigin", "orthoPxToMeter"]
EXID_EXTRA = ["traveledDistance", "latLaneCenterOffset", "laneWidth", "laneletId", "laneChange",
              "lonLaneletPos", "laneletLength", "leadDHW", "leadDV", "leadTHW", "leadTTC", "leadId",
              "rearId", "leftLeadId", "leftRearId", "leftAlongsideId", "rightLeadId", "rightRearId",
              "rightAlongsideId", "odrRoadId", "odrSectionNo", "odrLaneId"]
EXID_REC = ["recordingId", "locationId", "frameRate", "weekday", "startTime", "duration", "numTracks",
            "numVehicles", "numVRUs", "latLocation", "lonLocation", "xUtmOrigin", "yUtmOrigin",
            "orthoPxToMeter"]


def _fmt(v) -> str:
    if isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    return f"{float(v):.6f}".rstrip("0").rstrip(".") if math.isfinite(v) else "nan"


def write_csv(path: Path, header: list[str], rows: list[dict]) -> Path:
    lines = [",".join(header)]
    for r in rows:
        lines.append(",".join(_fmt(r.get(c, 0)) for c in header))
    path.write_text("\n".join(lines) + "\n")
    return path


# --- highD truth -----------------------------------------------------------------------------------

def highd_truth(n_frames: int = 125):
    """Three vehicles: a car changing from the inner to the outer lower lane (towards +x), a truck
    on the inner upper lane (towards -x) and a slow car (heading from the driving direction)."""
    f = np.arange(1, n_frames + 1)
    t = (f - 1) / RATE
    T = t[-1]
    c1 = (LOWER[0] + LOWER[1]) / 2
    c2 = (LOWER[1] + LOWER[2]) / 2
    yi1 = c1 + (c2 - c1) * (1 - np.cos(np.pi * t / T)) / 2          # image y, down
    dyi1 = (c2 - c1) * np.pi / T * np.sin(np.pi * t / T) / 2
    d2yi1 = (c2 - c1) * (np.pi / T) ** 2 * np.cos(np.pi * t / T) / 2
    veh = [
        dict(id=1, cls="Car", dir=2, L=4.5, W=1.9, xc=20 + 30 * t, vx=np.full_like(t, 30.0),
             ax=np.zeros_like(t), yi=yi1, vyi=dyi1, ayi=d2yi1),
        dict(id=2, cls="Truck", dir=1, L=12.0, W=2.5, xc=400 - 25 * t, vx=np.full_like(t, -25.0),
             ax=np.zeros_like(t), yi=np.full_like(t, (UPPER[1] + UPPER[2]) / 2), vyi=np.zeros_like(t),
             ayi=np.zeros_like(t)),
        dict(id=3, cls="Car", dir=2, L=4.0, W=1.8, xc=100 + 0.5 * t, vx=np.full_like(t, 0.5),
             ax=np.zeros_like(t), yi=np.full_like(t, c1), vyi=np.zeros_like(t), ayi=np.zeros_like(t)),
    ]
    for v in veh:
        v["frames"] = f
        v["t"] = t
        v["x"] = v["xc"]
        v["y"] = -v["yi"]
        v["vy"] = -v["vyi"]
        v["heading"] = np.arctan2(v["vy"], v["vx"]) if v["id"] != 3 else np.zeros_like(t)
    return veh


def highd_lane_id(yi: np.ndarray) -> np.ndarray:
    marks = UPPER + LOWER  # highD numbering: one id per interval, counted from the top from 1
    return np.searchsorted(np.array(marks), yi) + 1


def write_highd(folder: Path, veh=None, prefix: str = "01") -> list[Path]:
    veh = veh or highd_truth()
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for v in veh:
        lane = highd_lane_id(v["yi"])
        for i in range(len(v["t"])):
            rows.append({"frame": int(v["frames"][i]), "id": v["id"],
                         "x": v["xc"][i] - v["L"] / 2, "y": v["yi"][i] - v["W"] / 2,
                         "width": v["L"], "height": v["W"], "xVelocity": v["vx"][i],
                         "yVelocity": v["vyi"][i], "xAcceleration": v["ax"][i],
                         "yAcceleration": v["ayi"][i], "precedingId": 0, "followingId": 0,
                         "laneId": int(lane[i])})
    meta = [{"id": v["id"], "width": v["L"], "height": v["W"], "initialFrame": int(v["frames"][0]),
             "finalFrame": int(v["frames"][-1]), "numFrames": len(v["frames"]), "class": v["cls"],
             "drivingDirection": v["dir"], "minDHW": -1, "minTHW": -1, "minTTC": -1} for v in veh]
    rec = [{"id": int(prefix), "frameRate": 25, "locationId": 2, "speedLimit": -1, "month": "09.2017",
            "weekDay": "Wed", "startTime": "08:38", "duration": 5.0, "numVehicles": len(veh),
            "numCars": 2, "numTrucks": 1, "upperLaneMarkings": ";".join(map(str, UPPER)),
            "lowerLaneMarkings": ";".join(map(str, LOWER))}]
    return [write_csv(folder / f"{prefix}_tracks.csv", HIGHD_TRACKS, rows),
            write_csv(folder / f"{prefix}_tracksMeta.csv", HIGHD_META, meta),
            write_csv(folder / f"{prefix}_recordingMeta.csv", HIGHD_REC, rec)]


def test_registered():
    reg = load_converters()
    assert {"highd", "ind", "exid"} <= set(reg)
    assert reg["highd"].needs_map is False and reg["ind"].needs_map is True


def test_highd_map_lanes_follow_the_markings():
    net = load_map(highd_map(np.array(UPPER), np.array(LOWER), 0.0, 420.0))
    centres_upper = [(UPPER[i] + UPPER[i + 1]) / 2 for i in range(2)]
    centres_lower = [(LOWER[i] + LOWER[i + 1]) / 2 for i in range(2)]
    yi = np.array(centres_upper + centres_lower)
    proj = net.world_to_road(np.full(4, 200.0), -yi)
    assert proj.lane_id.tolist() == [3, 2, -2, -3]
    assert np.allclose(proj.lane_offset, 0.0, atol=1e-9)
    # borders: a point just inside each marking is in the lane, just outside is not
    inner = net.world_to_road(np.array([200.0, 200.0]), -np.array([UPPER[0] + 0.01, LOWER[-1] - 0.01]))
    outer = net.world_to_road(np.array([200.0, 200.0]), -np.array([UPPER[0] - 0.01, LOWER[-1] + 0.01]))
    assert inner.lane_id.tolist() == [3, -3] and (outer.n_candidates == 0).all()
    median = net.world_to_road(np.array([200.0]), -np.array([(UPPER[-1] + LOWER[0]) / 2 + 0.5]))
    assert median.lane_id.tolist() == [-1]
    with pytest.raises(ValueError):
        highd_map(np.array(LOWER), np.array(UPPER), 0, 1)


def test_highd_roundtrip_against_truth(tmp_path):
    veh = highd_truth()
    files = write_highd(tmp_path / "highd", veh)
    rec = convert("highd", [files[0]])
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist() == ["1", "2", "3"]
    assert p.column("class").to_pylist() == ["car", "truck", "car"]
    assert p.column("length").to_pylist() == [4.5, 12.0, 4.0]
    assert p.column("width").to_pylist() == [1.9, 2.5, 1.8]
    pid = s.column("participant_id").to_numpy()
    for k, v in enumerate(veh):
        m = pid == k
        assert np.allclose(s.column("time").to_numpy()[m], v["t"])
        assert np.allclose(s.column("x").to_numpy()[m], v["x"], atol=1e-5)
        assert np.allclose(s.column("y").to_numpy()[m], v["y"], atol=1e-5)
        assert np.allclose(s.column("vx").to_numpy()[m], v["vx"], atol=1e-5)
        assert np.allclose(s.column("vy").to_numpy()[m], v["vy"], atol=1e-5)
        dh = np.angle(np.exp(1j * (s.column("heading").to_numpy()[m] - v["heading"])))
        assert np.abs(dh).max() < 1e-5
        assert s.column("source_frame").to_numpy()[m].tolist() == v["frames"].tolist()
    # the truck drives towards -x: heading pi, in the upper carriageway's inner lane (left lane 2)
    h = s.column("heading").to_numpy()
    assert np.allclose(np.abs(h[pid == 1]), math.pi)
    lane = np.asarray(s.column("lane_id").to_pylist())
    assert (lane[pid == 1] == 2).all() and (lane[pid == 2] == -2).all()
    assert lane[pid == 0][0] == -2 and lane[pid == 0][-1] == -3
    road_s = s.column("road_s").to_numpy()
    x0 = math.floor(min(v["xc"].min() - v["L"] / 2 for v in veh) - 10.0)
    assert np.allclose(road_s, s.column("x").to_numpy() - x0)
    # uncertainty: GSD-based position std, velocity std, heading std from speed
    assert np.allclose(s.column("x_std").to_numpy(), 0.10106)
    assert np.allclose(s.column("heading_std").to_numpy()[pid == 1], 0.1 / 25.0)
    assert np.allclose(s.column("heading_std").to_numpy()[pid == 2], 0.1)
    # lane change event from laneId
    ev = rec.table("events")
    assert ev.num_rows == 1 and ev.column("participant_ids").to_pylist() == [[0]]
    meta = rec.meta
    assert meta.acquisition.method.value == "aerial"
    assert meta.provenance.value == "natural"
    assert meta.acquisition.not_observable == ["light_", "interior"]
    assert meta.nominal_rate_hz == 25.0
    assert meta.source.converter == "highd"
    assert sorted(i.file for i in meta.source.inputs) == ["01_recordingMeta.csv", "01_tracks.csv",
                                                          "01_tracksMeta.csv"]
    assert meta.extras["levelx"]["upperLaneMarkings"] == "8.51;12.59;16.43"
    assert meta.coverage.startswith("POLYGON")
    out = rec.write(tmp_path / "highd.aveas")
    report = aveas_format.validate(out)
    assert report.counts["error"] == 0, report


def test_highd_any_input_file_or_folder(tmp_path):
    files = write_highd(tmp_path / "h")
    a = convert("highd", [files[2]])
    b = convert("highd", [tmp_path / "h"])
    assert a.states.num_rows == b.states.num_rows == 375


def test_highd_with_given_map_and_options(tmp_path):
    files = write_highd(tmp_path / "h")
    xodr = tmp_path / "m.xodr"
    xodr.write_text(highd_map(np.array(UPPER), np.array(LOWER), -50.0, 500.0,
                              geo_reference="+proj=tmerc +lat_0=51 +lon_0=7 +k=1 +x_0=0 +y_0=0 "
                              "+ellps=WGS84 +units=m +no_defs"))
    rec = convert("highd", files, map_source=xodr, options={"pixel_std": 2.0, "gsd": 0.125})
    assert np.allclose(rec.states.column("x_std").to_numpy(), 0.25)
    assert abs(rec.meta.location.lat - 51.0) < 0.01


def _break(path: Path, line: int, col: str, value: str) -> None:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[line - 1].split(",")
    cells[header.index(col)] = value
    lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")


@pytest.mark.parametrize("which,line,col,value,match", [
    (0, 5, "x", "abc", r"01_tracks.csv: line 5: column 'x': 'abc' is not a number"),
    (0, 7, "id", "99", r"01_tracks.csv: line 7: track id 99 is not in tracksMeta.csv"),
    (0, 4, "height", "0", r"01_tracks.csv: line 4: column 'height': 0 is not a positive number"),
    (1, 3, "drivingDirection", "3", r"01_tracksMeta.csv: line 3: column 'drivingDirection': 3 is "
                                    r"neither 1 nor 2"),
    (2, 2, "upperLaneMarkings", "8.5;x", r"01_recordingMeta.csv: line 2: column 'upperLaneMarkings'"),
    (2, 2, "lowerLaneMarkings", "21.0", r"01_recordingMeta.csv: line 2: column 'lowerLaneMarkings'.*"
                                        r"at least two"),
    (2, 2, "frameRate", "0", r"01_recordingMeta.csv: line 2: column 'frameRate'"),
])
def test_highd_malformed_input_is_located(tmp_path, which, line, col, value, match):
    files = write_highd(tmp_path / "h")
    _break(files[which], line, col, value)
    with pytest.raises(aveas_format.FormatError, match=match):
        convert("highd", [files[0]])


def test_highd_missing_pieces(tmp_path):
    files = write_highd(tmp_path / "h")
    files[2].unlink()
    with pytest.raises(aveas_format.RecordingIOError, match="01_recordingMeta.csv: levelX file missing"):
        convert("highd", [files[0]])
    other = write_highd(tmp_path / "h", prefix="02")
    with pytest.raises(aveas_format.FormatError, match="inputs belong to 2 recordings"):
        convert("highd", [files[0], other[0]])
    p = tmp_path / "h" / "02_tracks.csv"
    text = p.read_text().splitlines()
    p.write_text("\n".join([text[0].replace(",xVelocity", ",xSpeed")] + text[1:]) + "\n")
    with pytest.raises(aveas_format.FormatError, match=r"02_tracks.csv: required column\(s\) "
                                                       r"\['xVelocity'\] missing"):
        convert("highd", [p])


def test_highd_duplicate_sample_is_located(tmp_path):
    files = write_highd(tmp_path / "h")
    lines = files[0].read_text().splitlines()
    files[0].write_text("\n".join(lines + [lines[3]]) + "\n")
    with pytest.raises(aveas_format.FormatError, match=rf"01_tracks.csv: line {len(lines) + 1}: "
                                                       "participant '1' sampled twice at time"):
        convert("highd", [files[0]])


# --- inD / exiD ----------------------------------------------------------------------------------

LAT0, LON0 = 50.78, 6.06
SITE_CRS = f"+proj=tmerc +lat_0={LAT0} +lon_0={LON0} +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
UTM = "EPSG:32632"


def ind_truth(n: int = 100):
    """In the site frame (the map's tmerc): a car along the road's lane, a pedestrian crossing."""
    t = np.arange(n) / RATE
    car = dict(id=0, cls="car", L=4.6, W=1.9, x=-40 + 12 * t + 0.5 * t ** 2, y=np.full(n, -1.75),
               vx=12 + t, vy=np.zeros(n), ax=np.ones(n), ay=np.zeros(n))
    car["heading"] = np.zeros(n)
    ped = dict(id=1, cls="pedestrian", L=0.0, W=0.0, x=np.full(n, 5.0), y=-8 + 1.4 * t,
               vx=np.zeros(n), vy=np.full(n, 1.4), ax=np.zeros(n), ay=np.zeros(n))
    ped["heading"] = np.full(n, math.pi / 2)
    for v in (car, ped):
        v["t"] = t
        v["frames"] = np.arange(n)
    return [car, ped]


def _site_to_utm(x, y, heading, vx, vy, ax, ay):
    """Site-frame truth -> UTM zone 32 (positions, and directions turned by the convergence)."""
    tr = pyproj.Transformer.from_crs(pyproj.CRS(SITE_CRS), UTM, always_xy=True)
    e, nn = tr.transform(x, y)
    e2, n2 = tr.transform(x + 1.0, y)
    rot = np.arctan2(np.asarray(n2) - nn, np.asarray(e2) - e)

    def r(a, b):
        return a * np.cos(rot) - b * np.sin(rot), a * np.sin(rot) + b * np.cos(rot)

    return np.asarray(e), np.asarray(nn), heading + rot, *r(vx, vy), *r(ax, ay)


def write_centre(folder: Path, veh, *, exid: bool = False, prefix: str = "07"):
    folder.mkdir(parents=True, exist_ok=True)
    e0, n0 = pyproj.Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(LON0, LAT0)
    x0, y0 = round(e0 - 60.0, 3), round(n0 + 40.0, 3)
    rows = []
    for v in veh:
        e, nn, h, vx, vy, ax, ay = _site_to_utm(v["x"], v["y"], v["heading"], v["vx"], v["vy"],
                                               v["ax"], v["ay"])
        for i in range(len(v["t"])):
            r = {"recordingId": int(prefix), "trackId": v["id"], "frame": int(v["frames"][i]),
                 "trackLifetime": i, "xCenter": e[i] - x0, "yCenter": nn[i] - y0,
                 "heading": math.degrees(h[i]) % 360.0, "width": v["W"], "length": v["L"],
                 "xVelocity": vx[i], "yVelocity": vy[i], "xAcceleration": ax[i],
                 "yAcceleration": ay[i], "lonVelocity": math.hypot(vx[i], vy[i])}
            if exid:
                r.update({"laneletId": "1001;1002" if i == 10 else ("1002" if i > 10 else "1001"),
                          "latLaneCenterOffset": "0.1;0.2" if i == 10 else "0.1",
                          "laneWidth": "3.5;3.5" if i == 10 else "3.5",
                          "lonLaneletPos": "1.0;0.0" if i == 10 else "1.0",
                          "laneletLength": "50;60" if i == 10 else "50",
                          "laneChange": 1 if (v["id"] == 0 and i == 50) else 0,
                          "leadId": -1, "rearId": -1, "leftAlongsideId": "-1",
                          "rightAlongsideId": "-1", "odrRoadId": 1, "odrSectionNo": 0,
                          "odrLaneId": -1})
            rows.append(r)
    meta = [{"recordingId": int(prefix), "trackId": v["id"], "initialFrame": 0,
             "finalFrame": len(v["t"]) - 1, "numFrames": len(v["t"]), "width": v["W"],
             "length": v["L"], "class": v["cls"]} for v in veh]
    rec = [{"recordingId": int(prefix), "locationId": 1, "frameRate": 25, "speedLimit": 13.89,
            "weekday": "Tuesday", "startTime": 8, "duration": 4.0, "numTracks": len(veh),
            "numVehicles": 1, "numVRUs": 1, "latLocation": LAT0, "lonLocation": LON0,
            "xUtmOrigin": x0, "yUtmOrigin": y0, "orthoPxToMeter": 0.0126999352667008}]
    header = IND_TRACKS + (EXID_EXTRA if exid else [])
    return [write_csv(folder / f"{prefix}_tracks.csv", header, rows),
            write_csv(folder / f"{prefix}_tracksMeta.csv", IND_META, meta),
            write_csv(folder / f"{prefix}_recordingMeta.csv", EXID_REC if exid else IND_REC, rec)]


@pytest.fixture(scope="module")
def site_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "site.xodr"
    p.write_text(straight_highway(length=200.0, lanes_right=1, lanes_left=1, x0=-100.0, y0=0.0,
                                  geo_reference=SITE_CRS))
    return p


def _check_truth(rec, veh, atol=2e-5, hatol=1e-5):
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    for k, v in enumerate(veh):
        m = pid == k
        assert np.allclose(s.column("x").to_numpy()[m], v["x"], atol=atol)
        assert np.allclose(s.column("y").to_numpy()[m], v["y"], atol=atol)
        dh = np.angle(np.exp(1j * (s.column("heading").to_numpy()[m] - v["heading"])))
        assert np.abs(dh).max() < hatol
        assert np.allclose(s.column("vx").to_numpy()[m], v["vx"], atol=1e-4)
        assert np.allclose(s.column("vy").to_numpy()[m], v["vy"], atol=1e-4)
        assert np.allclose(s.column("ax").to_numpy()[m], v["ax"], atol=1e-4)


def test_utm_crs_for():
    assert utm_crs_for(6.06, 50.78) == "EPSG:32632"
    assert utm_crs_for(-70.0, -33.0) == "EPSG:32719"


def test_ind_projected_through_the_map_crs(tmp_path, site_map):
    veh = ind_truth()
    files = write_centre(tmp_path / "ind", veh)
    rec = convert("ind", [files[0]], map_source=site_map, options={"dataset": "rounD"})
    _check_truth(rec, veh)
    p = rec.participants
    assert p.column("class").to_pylist() == ["car", "pedestrian"]
    assert p.column("length").to_pylist() == [4.6, 0.6]
    attrs = [json.loads(a) for a in p.column("attributes").to_pylist()]
    assert attrs[1]["size_assumed"] is True and "size_assumed" not in attrs[0]
    s = rec.states
    lane = np.asarray(s.column("lane_id").to_pylist(), dtype=object)
    pid = s.column("participant_id").to_numpy()
    assert (lane[pid == 0] == -1).all()
    assert np.allclose(s.column("time").to_numpy()[pid == 0], veh[0]["t"])
    assert rec.meta.acquisition.site.name == "rounD location 1"
    assert rec.meta.crs == SITE_CRS
    assert rec.meta.extras["levelx"]["utm_crs"] == UTM
    out = rec.write(tmp_path / "ind.aveas")
    assert aveas_format.validate(out).counts["error"] == 0


def test_ind_map_in_the_tracks_frame(tmp_path):
    """A map without geoReference is taken to be in the tracks' frame; crs = shifted UTM."""
    veh = ind_truth()
    files = write_centre(tmp_path / "ind", veh)
    local = tmp_path / "local.xodr"
    # under the tracks (x 20..75 m, y -48..-40 m): off the map would be map.mostly_off_road
    local.write_text(straight_highway(length=300.0, lanes_right=2, lanes_left=2, x0=-50.0, y0=-44.0))
    rec = convert("ind", files, map_source=local)
    tracks = np.genfromtxt(files[0], delimiter=",", names=True)
    s = rec.states
    assert np.allclose(s.column("x").to_numpy(), tracks["xCenter"])
    rm = np.genfromtxt(files[2], delimiter=",", names=True)
    lon, lat = pyproj.Transformer.from_crs(UTM, "EPSG:4326", always_xy=True).transform(
        tracks["xCenter"] + rm["xUtmOrigin"], tracks["yCenter"] + rm["yUtmOrigin"])
    assert np.allclose(s.column("lon").to_numpy(), lon, atol=1e-9)
    assert np.allclose(s.column("lat").to_numpy(), lat, atol=1e-9)
    assert rec.meta.crs == shifted_crs(UTM, float(rm["xUtmOrigin"]), float(rm["yUtmOrigin"]))
    assert aveas_format.validate(rec.write(tmp_path / "l.aveas")).counts["error"] == 0


def test_exid_lanelet_lists_and_lane_changes(tmp_path, site_map):
    veh = ind_truth()
    files = write_centre(tmp_path / "exid", veh, exid=True)
    rec = convert("exid", [tmp_path / "exid"], map_source=site_map)
    _check_truth(rec, veh)
    attrs = [json.loads(a) for a in rec.participants.column("attributes").to_pylist()]
    assert attrs[0]["lanelets"] == [1001, 1002] and attrs[1]["lanelets"] == [1001, 1002]
    ev = rec.table("events")
    assert ev.num_rows == 1 and ev.column("time_start").to_pylist() == [50 / RATE]
    assert rec.meta.acquisition.site.road_type.value == "motorway"
    assert aveas_format.validate(rec.write(tmp_path / "x.aveas")).counts["error"] == 0
    _break(files[0], 30, "laneletId", "1001;x")
    with pytest.raises(aveas_format.FormatError, match=r"07_tracks.csv: line 30: column 'laneletId'"):
        convert("exid", [files[0]], map_source=site_map)


@pytest.mark.parametrize("which,line,col,value,match", [
    (0, 9, "heading", "north", r"07_tracks.csv: line 9: column 'heading': 'north' is not a number"),
    (0, 12, "trackId", "5", r"07_tracks.csv: line 12: track id 5 is not in tracksMeta.csv"),
    (1, 2, "width", "0", r"07_tracksMeta.csv: line 2: track 0 \(car\) has no positive width"),
    (2, 2, "xUtmOrigin", "", r"07_recordingMeta.csv: line 2: column 'xUtmOrigin' is empty"),
])
def test_ind_malformed_input_is_located(tmp_path, site_map, which, line, col, value, match):
    files = write_centre(tmp_path / "ind", ind_truth())
    _break(files[which], line, col, value)
    with pytest.raises(aveas_format.FormatError, match=match):
        convert("ind", [files[0]], map_source=site_map)


def test_ind_needs_a_map(tmp_path):
    files = write_centre(tmp_path / "ind", ind_truth())
    with pytest.raises(aveas_format.UsageError, match="needs a map"):
        convert("ind", [files[0]])


def test_cli_convert_highd_without_map(tmp_path):
    import subprocess
    import sys

    files = write_highd(tmp_path / "h")
    out = tmp_path / "cli.aveas"
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "highd",
                          str(files[0]), "-o", str(out), "-O", "pixel_std=2", "-O",
                          "license=CC-BY-4.0", "-O", "start_time=2017-11-03T08:00:00Z"],
                         capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "valid" in res.stderr and out.is_dir()
    res = subprocess.run([sys.executable, "-m", "aveas_format", "convert", "--from", "ind",
                          str(files[0]), "-o", str(tmp_path / "x.aveas")], capture_output=True,
                         text=True)
    assert res.returncode == 2 and "needs a map" in res.stderr


def test_highd_unobserved_outside_the_footprint(tmp_path):
    """The built map's surroundings outside the drone's footprint (the coverage) are one
    outside_coverage region for the whole recording; no state lies in it, and validate no longer
    asks for an unobserved table."""
    import shapely

    import aveas_format

    rec = convert("highd", [write_highd(tmp_path / "highd")[0]])
    un = rec.unobserved
    assert un.num_rows == 1 and un["kind"].to_pylist() == ["outside_coverage"]
    assert un["time_start"][0].as_py() == 0.0
    assert un["time_end"][0].as_py() == pytest.approx(float(np.max(rec.states["time"].to_numpy())))
    region = shapely.from_wkb(un["geometry"][0].as_py())
    cover = shapely.from_wkt(rec.meta.coverage)
    assert region.is_valid and shapely.intersection(region, cover).area < 1e-6
    pts = shapely.points(rec.states["x"].to_numpy(), rec.states["y"].to_numpy())
    assert not shapely.contains(region, pts).any()
    codes = aveas_format.validate(rec).codes
    assert "unobserved.table_missing" not in codes and "unobserved.state_inside" not in codes
