"""Infrastructure LWIR camera -> recording: a synthetic pinhole camera 10 m above the road
(analytic ground homography), surveyed landmarks, MOTChallenge pixel tracks."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.converters.infra_lwir import estimate_homography
from aveas_format.opendrive.builder import straight_highway

GEO = "+proj=tmerc +lat_0=52.5 +lon_0=13.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
CAM = np.array([-20.0, -4.0, 10.0])
PITCH = math.radians(20.0)
K = np.array([[800.0, 0, 320.0], [0, 800.0, 256.0], [0, 0, 1]])
_z = np.array([math.cos(PITCH), 0.0, -math.sin(PITCH)])
_x = np.array([0.0, -1.0, 0.0])
R = np.stack([_x, np.cross(_z, _x), _z])
RATE = 25.0
NF = 50
# (id, y, x(t), MOT17 class)
CARS = [(1, -1.75, lambda t: 10 + 15 * t, 3), (2, -8.75, lambda t: 60 + 10 * t, 3)]


def project(x, y):
    p = (K @ (R @ (np.stack([x, y, np.zeros_like(x)]) - CAM[:, None])))
    return p[0] / p[2], p[1] / p[2]


@pytest.fixture(scope="module")
def road_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "road.xodr"
    p.write_text(straight_highway(length=300.0, lanes_right=3, x0=-50.0, geo_reference=GEO))
    return p


def write_landmarks(p):
    """Ten ground landmarks of the camera (:func:`project`) as the converter reads them."""
    xs = np.array([0.0, 0.0, 30.0, 30.0, 60.0, 60.0, 100.0, 100.0, 15.0, 80.0])
    ys = np.array([0.0, -10.5, 0.0, -10.5, 2.0, -10.5, 0.0, -10.5, -5.0, -3.0])
    u, v = project(xs, ys)
    p.write_text("name,u,v,x,y\n" + "".join(f"L{i},{a:.6f},{b:.6f},{c},{d}\n"
                                           for i, (a, b, c, d) in enumerate(zip(u, v, xs, ys))))
    return p


@pytest.fixture(scope="module")
def landmarks(tmp_path_factory):
    return write_landmarks(tmp_path_factory.mktemp("lm") / "landmarks.csv")


def mot_lines(nine=False):
    out = []
    for k in range(1, NF + 1):
        t = (k - 1) / RATE
        for tid, y, fx, cls in CARS:
            u, v = project(np.array([fx(t)]), np.array([y]))
            w, h = 40.0, 30.0
            tail = f"{cls},1.0" if nine else "-1,-1,-1"
            out.append(f"{k},{tid},{u[0] - w / 2:.6f},{v[0] - h:.6f},{w},{h},1,{tail}")
    return out


@pytest.fixture(scope="module")
def mot(tmp_path_factory):
    p = tmp_path_factory.mktemp("mot") / "gt.txt"
    p.write_text("\n".join(mot_lines()) + "\n")
    return p


def test_registered():
    assert "infra-lwir" in load_converters()


def test_homography_recovers_the_camera():
    xs, ys = np.meshgrid([0.0, 40.0, 90.0], [-10.0, -4.0, 2.0])
    u, v = project(xs.ravel(), ys.ravel())
    h, cov, rms = estimate_homography(np.c_[u, v], np.c_[xs.ravel(), ys.ravel()])
    P = K @ np.c_[R[:, :2], -R @ CAM]  # ground -> pixel
    h_true = np.linalg.inv(P)
    h_true /= h_true[2, 2]
    assert h == pytest.approx(h_true, rel=1e-6, abs=1e-9) and rms < 1e-6
    assert cov.shape == (8, 8) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_bottom_centre(mot, landmarks, road_map, tmp_path):
    rec = convert("infra-lwir", [mot, landmarks], map_source=road_map,
                  options={"ground_point": "bottom_centre"})
    s = rec.states
    pid, t = s.column("participant_id").to_numpy(), s.column("time").to_numpy()
    for i, (tid, y, fx, _) in enumerate(CARS):
        sel = pid == i
        assert t[sel] == pytest.approx(np.arange(NF) / RATE)
        assert s.column("x").to_numpy()[sel] == pytest.approx(fx(t[sel]), abs=1e-4)
        assert s.column("y").to_numpy()[sel] == pytest.approx(y, abs=1e-4)
    assert s.column("vx").to_numpy()[pid == 0] == pytest.approx(15.0, abs=1e-3)
    assert np.allclose(s.column("heading").to_numpy(), 0.0, atol=1e-4)
    assert rec.participants.column("source_id").to_pylist() == ["1", "2"]
    assert rec.meta.acquisition.method.value == "infrastructure_lwir"
    report = aveas_format.validate(rec.write(tmp_path / "lwir.aveas"))
    assert report.counts["error"] == 0, report


def test_footprint_centre_and_fov(mot, landmarks, road_map):
    rec = convert("infra-lwir", [mot, landmarks], map_source=road_map)
    s = rec.states
    pid, t = s.column("participant_id").to_numpy(), s.column("time").to_numpy()
    x, y = s.column("x").to_numpy(), s.column("y").to_numpy()
    # the bottom centre is the car's near edge: the centre is ~ half a car length further away
    shift = np.hypot(x[pid == 0] - CARS[0][2](t[pid == 0]), y[pid == 0] - CARS[0][1])
    assert shift == pytest.approx(2.25, abs=0.1)
    assert rec.participants.column("length").to_pylist() == [4.5, 4.5]
    u = rec.table("unobserved")
    assert "field_of_view" in u.column("kind").to_pylist()
    cov = shapely.from_wkt(rec.meta.coverage)
    assert cov.contains(shapely.Point(30.0, -5.0)) and not cov.contains(shapely.Point(-30.0, -5.0))


def test_pixel_noise_propagation_matches_monte_carlo(mot, landmarks, road_map):
    """Exact landmarks: the position covariance is J_p C_px J_p^T; compare with sampling."""
    rec = convert("infra-lwir", [mot, landmarks], map_source=road_map,
                  options={"ground_point": "bottom_centre", "landmark_pixel_std": 1e-6,
                           "landmark_map_std": 1e-6, "pixel_std": 2.0})
    s = rec.states
    row = int(np.flatnonzero(s.column("participant_id").to_numpy() == 1)[0])
    x0, y0 = CARS[1][2](0.0), CARS[1][1]
    u0, v0 = project(np.array([x0]), np.array([y0]))
    rng = np.random.default_rng(0)
    n = 200_000
    du = rng.normal(0, 2.0 / math.sqrt(2), n)
    dv = rng.normal(0, 2.0, n)
    P = K @ np.c_[R[:, :2], -R @ CAM]
    Hi = np.linalg.inv(P)
    g = Hi @ np.stack([u0[0] + du, v0[0] + dv, np.ones(n)])
    gx, gy = g[0] / g[2], g[1] / g[2]
    assert s.column("x_std")[row].as_py() == pytest.approx(gx.std(), rel=0.02)
    assert s.column("y_std")[row].as_py() == pytest.approx(gy.std(), rel=0.02)
    assert s.column("xy_corr")[row].as_py() == pytest.approx(np.corrcoef(gx, gy)[0, 1], abs=0.02)


def test_landmark_noise_adds_homography_uncertainty(mot, landmarks, road_map, tmp_path):
    rec0 = convert("infra-lwir", [mot, landmarks], map_source=road_map,
                   options={"landmark_pixel_std": 1e-6, "landmark_map_std": 1e-6})
    rec1 = convert("infra-lwir", [mot, landmarks], map_source=road_map,
                   options={"landmark_map_std": 0.2})
    s0 = rec0.states.column("x_std").to_numpy()
    s1 = rec1.states.column("x_std").to_numpy()
    assert np.all(s1 > s0)


def test_csv_with_class_and_mot17_classes(landmarks, road_map, tmp_path):
    p9 = tmp_path / "gt9.txt"
    p9.write_text("\n".join(mot_lines(nine=True)) + "\n")
    rec = convert("infra-lwir", [p9, landmarks], map_source=road_map)
    assert rec.participants.column("class").to_pylist() == ["car", "car"]
    csv = tmp_path / "tracks.csv"
    lines = ["frame,track_id,class,bb_left,bb_top,bb_width,bb_height,conf"]
    for ln in mot_lines():
        f = ln.split(",")
        lines.append(",".join([f[0], f[1], "truck" if f[1] == "2" else "car", *f[2:7]]))
    csv.write_text("\n".join(lines) + "\n")
    rec = convert("infra-lwir", [csv], map_source=road_map, options={"landmarks": str(landmarks)})
    assert rec.participants.column("class").to_pylist() == ["car", "truck"]
    assert rec.participants.column("length").to_pylist() == [4.5, 10.0]


def test_malformed_inputs_are_located(mot, landmarks, road_map, tmp_path):
    bad = tmp_path / "bad.txt"
    lines = mot_lines()
    lines[3] = "4,2,abc,100,40,30,1,-1,-1,-1"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(aveas_format.FormatError, match=r"bad.txt: line 4: field 3 \(bb_left\): 'abc'"):
        convert("infra-lwir", [bad, landmarks], map_source=road_map)
    lines = mot_lines()
    lines[5] = "3,2,100,100,40,-30,1,-1,-1,-1"
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(aveas_format.FormatError, match=r"bad.txt: line 6: column 'bb_height': value must be positive"):
        convert("infra-lwir", [bad, landmarks], map_source=road_map)
    few = tmp_path / "few.csv"
    few.write_text("u,v,x,y\n1,2,3,4\n5,6,7,8\n9,1,2,3\n")
    with pytest.raises(aveas_format.FormatError, match=r"few.csv: 3 landmarks; the ground homography needs at least 4"):
        convert("infra-lwir", [mot, few], map_source=road_map)
    with pytest.raises(aveas_format.FormatError, match=r"no landmark table"):
        convert("infra-lwir", [mot], map_source=road_map)
    lm = tmp_path / "lm.csv"
    lm.write_text("u,v,x,y\n1,2,3,4\n5,x6,7,8\n")
    with pytest.raises(aveas_format.FormatError, match=r"lm.csv: line 3: column 'v': 'x6' is not a number"):
        convert("infra-lwir", [mot, lm], map_source=road_map)


@pytest.mark.parametrize("mot_class, kept_as", [(7, "pedestrian"), (8, "other"), (12, "other"),
                                                 (2, "pedestrian"), (9, "other")])
def test_mot_classes_that_are_no_road_users(landmarks, road_map, tmp_path, mot_class, kept_as):
    """MOTChallenge ground truth labels static persons, distractors, occluders, reflections and
    riders too: skipped with a count by default, kept with keep_non_road_users; a crowd (13) never."""
    def relabel(ln, tid, cls):
        f = ln.split(",")
        return ",".join([f[0], tid, *f[2:7], str(cls), f[8]])

    lines = [relabel(ln, "2", mot_class) if ln.split(",")[1] == "2" else ln for ln in mot_lines(nine=True)]
    lines += [relabel(ln, "9", 13) for ln in mot_lines(nine=True) if ln.split(",")[1] == "1"]
    p = tmp_path / "gt.txt"
    p.write_text("\n".join(lines) + "\n")
    from aveas_format.converters.labels import MOT_CLASS_IDS

    name = MOT_CLASS_IDS[mot_class]
    with pytest.warns(UserWarning, match=rf"skipped 2 tracks: 1 {name} \(no road user\); 1 crowd"):
        rec = convert("infra-lwir", [p, landmarks], map_source=road_map)
    assert rec.participants.column("class").to_pylist() == ["car"]
    with pytest.warns(UserWarning, match=r"skipped 1 tracks: 1 crowd"):
        rec = convert("infra-lwir", [p, landmarks], map_source=road_map,
                      options={"keep_non_road_users": True})
    assert rec.participants.column("class").to_pylist() == ["car", kept_as]
