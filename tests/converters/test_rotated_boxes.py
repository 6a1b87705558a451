"""Rotated-box tracks + world file / GDAL geotransform -> recording, on fixtures made from an
analytic truth in the map frame (projected to pixels through the inverse georeference)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pyproj
import pytest

import aveas_format
from aveas_format.converters import convert, load_converters
from aveas_format.converters.rotated_boxes import local_linear_velocity, read_world_file
from aveas_format.opendrive.builder import straight_highway

SITE_CRS = "+proj=tmerc +lat_0=48.9 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
RATE = 20.0
GSD = 0.125
THETA = math.radians(20.0)
#: world = C0 + A @ (u, v), u right, v down (corner-based pixel coordinates)
A_SIM = GSD * np.array([[math.cos(THETA), math.sin(THETA)], [math.sin(THETA), -math.cos(THETA)]])
C0 = np.array([-160.0, 60.0])


@pytest.fixture(scope="module")
def site_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "site.xodr"
    p.write_text(straight_highway(length=400.0, lanes_right=2, lanes_left=2, x0=-200.0, y0=0.0,
                                  geo_reference=SITE_CRS))
    return p


def truth(n: int = 80):
    t = np.arange(n) / RATE
    car = dict(id=11, L=4.5, W=1.8, x=-100 + 20 * t + 0.5 * t ** 2, y=np.full(n, -1.75),
               heading=np.zeros(n), vx=20 + t, vy=np.zeros(n), scores={"car": 0.8, "van": 0.2})
    truck = dict(id=12, L=16.0, W=2.5, x=100 - 15 * t, y=np.full(n, 1.75), heading=np.full(n, math.pi),
                 vx=np.full(n, -15.0), vy=np.zeros(n), scores={"truck": 0.7, "bus": 0.3})
    parked = dict(id=13, L=4.0, W=1.7, x=np.full(n, 0.0), y=np.full(n, -9.0),
                  heading=np.full(n, 0.3), vx=np.zeros(n), vy=np.zeros(n), scores={"car": 1.0})
    for v in (car, truck, parked):
        v["t"] = t
        v["frame"] = np.arange(n)
    return [car, truck, parked]


def to_pixels(v, A=A_SIM, c=C0, X=None, Y=None, heading=None):
    """Box in pixels (cx, cy, w, h, angle deg) and DOTA corners of a truth vehicle."""
    X = v["x"] if X is None else X
    Y = v["y"] if Y is None else Y
    h = v["heading"] if heading is None else heading
    Ai = np.linalg.inv(A)
    uv = Ai @ np.vstack([X - c[0], Y - c[1]])
    d = Ai @ np.vstack([np.cos(h), np.sin(h)])
    nrm = Ai @ np.vstack([-np.sin(h), np.cos(h)])
    ang = np.degrees(np.arctan2(d[1], d[0]))
    w = v["L"] * np.hypot(*d)
    hh = v["W"] * np.hypot(*nrm)
    corners = []
    for sl, sw in ((1, 1), (1, -1), (-1, -1), (-1, 1)):
        wx = X + sl * v["L"] / 2 * np.cos(h) - sw * v["W"] / 2 * np.sin(h)
        wy = Y + sl * v["L"] / 2 * np.sin(h) + sw * v["W"] / 2 * np.cos(h)
        corners.append(Ai @ np.vstack([wx - c[0], wy - c[1]]))
    return uv, w, hh, ang, corners


def write_tracks(path: Path, veh, *, form: str = "centre", time_col: str = "frame",
                 scramble: bool = True, **pix) -> Path:
    rng = np.random.default_rng(1)
    header = ["frame" if time_col == "frame" else "time", "track_id"]
    header += ["cx", "cy", "w", "h", "angle"] if form == "centre" else \
        [f"{a}{i}" for i in range(1, 5) for a in ("x", "y")]
    classes = sorted({k for v in veh for k in v["scores"]})
    header += [f"score_{k}" for k in classes]
    lines = [",".join(header)]
    rows = []
    for v in veh:
        uv, w, h, ang, corners = to_pixels(v, **pix)
        for i in range(len(v["t"])):
            r = [str(int(v["frame"][i])) if time_col == "frame" else repr(float(v["t"][i])),
                 str(v["id"])]
            if form == "centre":
                wi, hi, ai = w[i], h[i], ang[i]
                if scramble and rng.random() < 0.3:   # the same box, axis flipped by 180 deg
                    ai += 180.0
                if scramble and rng.random() < 0.3:   # the same box, w/h swapped, axis +90 deg
                    wi, hi, ai = hi, wi, ai + 90.0
                r += [repr(float(uv[0, i])), repr(float(uv[1, i])), repr(float(wi)), repr(float(hi)),
                      repr(float(ai))]
            else:
                k0 = int(rng.integers(4)) if scramble else 0   # any starting corner
                for k in range(4):
                    cc = corners[(k0 + k) % 4]
                    r += [repr(float(cc[0, i])), repr(float(cc[1, i]))]
            r += [repr(v["scores"].get(k, 0.0)) for k in classes]
            rows.append(r)
    rows = [rows[i] for i in rng.permutation(len(rows))] if scramble else rows
    path.write_text("\n".join(lines + [",".join(r) for r in rows]) + "\n")
    return path


def write_world_file(path: Path, A=A_SIM, c=C0) -> Path:
    centre = c + A @ np.array([0.5, 0.5])  # the world file names the upper-left pixel's centre
    vals = [A[0, 0], A[1, 0], A[0, 1], A[1, 1], centre[0], centre[1]]
    path.write_text("\n".join(repr(float(v)) for v in vals) + "\n")
    return path


def check_truth(rec, veh, atol=1e-6, hatol=1e-9):
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    src = rec.participants.column("source_id").to_pylist()
    for v in veh:
        k = src.index(str(v["id"]))
        m = pid == k
        assert np.allclose(s.column("time").to_numpy()[m], v["t"])
        assert np.allclose(s.column("x").to_numpy()[m], v["x"], atol=atol)
        assert np.allclose(s.column("y").to_numpy()[m], v["y"], atol=atol)
        dh = np.angle(np.exp(1j * (s.column("heading").to_numpy()[m] - v["heading"])))
        assert np.abs(dh).max() < hatol
        vx = s.column("vx").to_numpy()[m]
        # interior samples: a symmetric regression window is exact for constant acceleration
        assert np.allclose(vx[10:-10], v["vx"][10:-10], atol=1e-4)
        # at the ends the window is one-sided: bias a * window / 4 at most
        assert np.allclose(vx, v["vx"], atol=0.2)
    p = rec.participants
    for v in veh:
        k = src.index(str(v["id"]))
        assert p.column("length").to_pylist()[k] == pytest.approx(v["L"], abs=1e-6)
        assert p.column("width").to_pylist()[k] == pytest.approx(v["W"], abs=1e-6)


def test_registered():
    assert "rotated-boxes" in load_converters()


def centre_inputs(folder):
    """The analytic truth, its centre-form box table, a world file and a .prj in ``folder``."""
    veh = truth()
    tracks = write_tracks(folder / "tracks.csv", veh)
    tfw = write_world_file(folder / "ortho.tfw")
    prj = folder / "ortho.prj"
    prj.write_text(SITE_CRS)
    return veh, [tracks, tfw, prj]


def test_centre_form_with_world_file(tmp_path, site_map):
    veh, inputs = centre_inputs(tmp_path)
    rec = convert("rotated-boxes", inputs, map_source=site_map,
                  options={"frame_rate": RATE, "image_size": [3000, 1500]})
    check_truth(rec, veh)
    p, s = rec.participants, rec.states
    assert p.column("source_id").to_pylist()[0] in {"11", "12", "13"}
    by_src = dict(zip(p.column("source_id").to_pylist(), p.column("class").to_pylist()))
    assert by_src == {"11": "car", "12": "truck", "13": "car"}
    pmf = {src: row for src, row in zip(p.column("source_id").to_pylist(),
                                          p.column("class_pmf").to_pylist())}
    assert pmf["11"]["car"] == pytest.approx(0.8) and pmf["11"]["van"] == pytest.approx(0.2)
    assert pmf["12"]["bus"] == pytest.approx(0.3)
    # similarity transform: isotropic pixel noise stays isotropic, scaled by the GSD
    assert np.allclose(s.column("x_std").to_numpy(), GSD)
    assert np.allclose(s.column("y_std").to_numpy(), GSD)
    assert np.allclose(s.column("xy_corr").to_numpy(), 0.0, atol=1e-6)
    vstd = s.column("vx_std").to_numpy()
    assert np.all(vstd > 0) and np.all(vstd < 1.0)
    lane = np.asarray(s.column("lane_id").to_pylist(), dtype=object)
    pid = s.column("participant_id").to_numpy()
    k = p.column("source_id").to_pylist().index("11")
    assert (lane[pid == k] == -1).all()
    meta = rec.meta
    assert meta.acquisition.method.value == "aerial" and meta.provenance.value == "natural"
    assert meta.acquisition.platform == "aerial camera, GSD 0.125 m"
    assert meta.coverage.startswith("POLYGON")
    assert sorted(i.file for i in meta.source.inputs) == ["ortho.prj", "ortho.tfw", "tracks.csv"]
    out = rec.write(tmp_path / "boxes.aveas")
    report = aveas_format.validate(out)
    assert report.counts["error"] == 0, report


def test_corner_form_with_geotransform_equals_world_file(tmp_path, site_map):
    veh = truth()
    tracks = write_tracks(tmp_path / "dota.csv", veh, form="corners")
    gt = [C0[0], A_SIM[0, 0], A_SIM[0, 1], C0[1], A_SIM[1, 0], A_SIM[1, 1]]
    rec = convert("rotated-boxes", [tracks], map_source=site_map,
                  options={"frame_rate": RATE, "geotransform": gt, "crs": SITE_CRS})
    check_truth(rec, veh)
    tfw = write_world_file(tmp_path / "o.jgw")
    rec2 = convert("rotated-boxes", [tracks, tfw], map_source=site_map,
                   options={"frame_rate": RATE, "crs": SITE_CRS})
    assert np.allclose(rec2.states.column("x").to_numpy(), rec.states.column("x").to_numpy(),
                       atol=1e-9)
    # the same numbers read as pixel-centre coordinates sit half a pixel further along +u, +v
    rec3 = convert("rotated-boxes", [tracks, tfw], map_source=site_map,
                   options={"frame_rate": RATE, "crs": SITE_CRS, "pixel_origin": "center"})
    d = A_SIM @ np.array([0.5, 0.5])
    assert np.allclose(rec3.states.column("x").to_numpy() - rec.states.column("x").to_numpy(), d[0])
    assert np.allclose(rec3.states.column("y").to_numpy() - rec.states.column("y").to_numpy(), d[1])


def test_gdal_aux_xml(tmp_path, site_map):
    veh = truth()
    tracks = write_tracks(tmp_path / "t.parquet.csv", veh, time_col="time")
    import pyarrow.csv as pacsv

    table = pacsv.read_csv(tracks)
    pq.write_table(table, tmp_path / "t.parquet")
    aux = tmp_path / "ortho.tif.aux.xml"
    gt = [C0[0], A_SIM[0, 0], A_SIM[0, 1], C0[1], A_SIM[1, 0], A_SIM[1, 1]]
    wkt = pyproj.CRS(SITE_CRS).to_wkt()
    aux.write_text(f"<PAMDataset>\n  <SRS>{wkt}</SRS>\n  <GeoTransform> "
                   f"{', '.join(repr(float(g)) for g in gt)}</GeoTransform>\n</PAMDataset>\n")
    rec = convert("rotated-boxes", [tmp_path / "t.parquet", aux], map_source=site_map)
    check_truth(rec, veh)


def test_other_crs_is_projected_with_convergence(tmp_path, site_map):
    """Georeference in UTM 32N, map in a transverse Mercator at the site."""
    veh = truth()
    to_utm = pyproj.Transformer.from_crs(pyproj.CRS(SITE_CRS), "EPSG:32632", always_xy=True)
    e0, n0 = to_utm.transform(-160.0, 60.0)
    c_utm = np.array([round(e0, 2), round(n0, 2)])
    for v in veh:
        e, nn = (np.asarray(a) for a in to_utm.transform(v["x"], v["y"]))
        e2, n2 = (np.asarray(a) for a in to_utm.transform(v["x"] + 1.0, v["y"]))
        v["E"], v["N"], v["H"] = e, nn, v["heading"] + np.arctan2(n2 - nn, e2 - e)
    path = tmp_path / "utm.csv"
    rows = ["time,track_id,cx,cy,w,h,angle,class,score"]
    for v in veh:
        uv, w, h, ang, _ = to_pixels(v, c=c_utm, X=v["E"], Y=v["N"], heading=v["H"])
        for i in range(len(v["t"])):
            rows.append(",".join(repr(float(a)) for a in (v["t"][i], v["id"], uv[0, i], uv[1, i],
                                                           w[i], h[i], ang[i]))
                        + f",{'large-vehicle' if v['L'] > 10 else 'small-vehicle'},0.9")
    path.write_text("\n".join(rows) + "\n")
    wf = write_world_file(tmp_path / "utm.wld", c=c_utm)
    rec = convert("rotated-boxes", [path, wf], map_source=site_map, options={"crs": "EPSG:32632"})
    check_truth(rec, veh, atol=1e-4, hatol=1e-6)
    p = rec.participants
    assert p.column("class").to_pylist() == ["car", "truck", "car"]
    assert p.column("class_pmf").to_pylist()[0]["car"] == pytest.approx(0.9)
    assert aveas_format.validate(rec.write(tmp_path / "u.aveas")).counts["error"] == 0


def test_anisotropic_pixel_noise_propagates_to_covariance(tmp_path, site_map):
    A = np.array([[0.10, 0.05], [0.02, -0.20]])
    c = np.array([-150.0, 80.0])
    v = truth(20)[0]
    uv, w, h, ang, _ = to_pixels(v, A=A, c=c)
    path = tmp_path / "n.csv"
    rows = ["time,track_id,cx,cy,w,h,angle,class,cx_std,cy_std,cxcy_corr"]
    for i in range(len(v["t"])):
        rows.append(",".join(repr(float(a)) for a in (v["t"][i], 7, uv[0, i], uv[1, i], w[i], h[i],
                                                       ang[i])) + ",car,1.5,2.0,0.3")
    path.write_text("\n".join(rows) + "\n")
    gt = [c[0], A[0, 0], A[0, 1], c[1], A[1, 0], A[1, 1]]
    rec = convert("rotated-boxes", [path], map_source=site_map,
                  options={"geotransform": gt, "crs": SITE_CRS})
    sp = np.array([[1.5 ** 2, 0.3 * 1.5 * 2.0], [0.3 * 1.5 * 2.0, 2.0 ** 2]])
    cov = A @ sp @ A.T
    s = rec.states
    assert np.allclose(s.column("x_std").to_numpy(), math.sqrt(cov[0, 0]))
    assert np.allclose(s.column("y_std").to_numpy(), math.sqrt(cov[1, 1]))
    rho = cov[0, 1] / math.sqrt(cov[0, 0] * cov[1, 1])
    assert np.allclose(s.column("xy_corr").to_numpy(), rho, atol=1e-6)
    assert np.allclose(s.column("x").to_numpy(), v["x"], atol=1e-6)
    assert np.allclose(s.column("vx").to_numpy()[5:-5], v["vx"][5:-5], atol=1e-6)


def test_local_linear_velocity_std_matches_monte_carlo():
    rng = np.random.default_rng(0)
    t = np.tile(np.arange(50) / 20.0, 2)
    pid = np.repeat([0, 1], 50)
    est = []
    for _ in range(400):
        x = 3.0 * t + rng.normal(0, 0.1, len(t))
        vx, _, g = local_linear_velocity(pid, t, x, np.zeros_like(t), 0.5)
        est.append(vx)
    est = np.array(est)
    assert abs(est.mean() - 3.0) < 0.02
    assert np.allclose(est.std(axis=0), 0.1 * g, rtol=0.15)


def test_read_world_file_pixel_centre(tmp_path):
    A, c = read_world_file(write_world_file(tmp_path / "a.tfw"))
    assert np.allclose(A, A_SIM) and np.allclose(c, C0)


@pytest.mark.parametrize("case,match", [
    ("wf_short", r"o.tfw: a world file has 6 numbers"),
    ("wf_text", r"o.tfw: line 3: world file value 'abc' is not a number"),
    ("no_crs", r"o.tfw: the georeference has no CRS"),
    ("no_georef", r"tracks.csv: no georeference"),
    ("bad_cx", r"tracks.csv: line 4: column 'cx': 'abc' is not a number"),
    ("bad_class", r"tracks.csv: line 3: column 'class': 'spaceship' is not a known class"),
    ("no_rate", r"tracks.csv: the table has 'frame' but no 'time'"),
    ("no_box", r"tracks.csv: the table needs box columns"),
    ("dup", r"tracks.csv: line 4: participant '1' sampled twice"),
])
def test_malformed_input_is_located(tmp_path, site_map, case, match):
    tracks = tmp_path / "tracks.csv"
    tracks.write_text("frame,track_id,cx,cy,w,h,angle,class\n0,1,100,100,36,14,10,car\n"
                      "1,1,101,100,36,14,10,car\n2,1,102,100,36,14,10,car\n")
    wf = write_world_file(tmp_path / "o.tfw")
    inputs = [tracks, wf]
    opts = {"frame_rate": 20.0, "crs": SITE_CRS}
    lines = tracks.read_text().splitlines()
    if case == "wf_short":
        wf.write_text("\n".join(wf.read_text().splitlines()[:5]))
    elif case == "wf_text":
        wl = wf.read_text().splitlines()
        wl[2] = "abc"
        wf.write_text("\n".join(wl))
    elif case == "no_crs":
        opts.pop("crs")
    elif case == "no_georef":
        inputs = [tracks]
    elif case == "bad_cx":
        lines[3] = lines[3].replace("102", "abc")
    elif case == "bad_class":
        lines[2] = lines[2].replace("car", "spaceship")
    elif case == "no_rate":
        opts.pop("frame_rate")
    elif case == "no_box":
        lines = [ln.rsplit(",", 3)[0] for ln in lines]
        lines = [",".join(ln.split(",")[:4]) + ",car" if i else "frame,track_id,cx,cy,class"
                 for i, ln in enumerate(lines)]
    elif case == "dup":
        lines[3] = lines[2]
    tracks.write_text("\n".join(lines) + "\n")
    with pytest.raises((aveas_format.FormatError, aveas_format.RecordingIOError), match=match):
        convert("rotated-boxes", inputs, map_source=site_map, options=opts)


def test_participant_attributes_count_boxes(tmp_path, site_map):
    veh = truth(10)
    tracks = write_tracks(tmp_path / "tracks.csv", veh)
    rec = convert("rotated-boxes", [tracks, write_world_file(tmp_path / "o.pgw")],
                  map_source=site_map, options={"frame_rate": RATE, "crs": SITE_CRS})
    assert [json.loads(a)["boxes"] for a in rec.participants.column("attributes").to_pylist()] == \
        [10, 10, 10]
    assert rec.states.column("source_frame").to_pylist()[:3] == [0, 1, 2]


def test_unobserved_outside_the_image(tmp_path, site_map):
    """With the image size known, the map's area outside the image footprint is unobserved
    (outside_coverage) for the whole recording; without it, nothing is claimed."""
    import shapely

    _, inputs = centre_inputs(tmp_path)
    rec = convert("rotated-boxes", inputs, map_source=site_map,
                  options={"frame_rate": RATE, "image_size": [3000, 1500]})
    un = rec.unobserved
    assert un["kind"].to_pylist() == ["outside_coverage"]
    region = shapely.from_wkb(un["geometry"][0].as_py())
    assert shapely.intersection(region, shapely.from_wkt(rec.meta.coverage)).area < 1e-3
    bare = convert("rotated-boxes", inputs, map_source=site_map, options={"frame_rate": RATE})
    assert bare.unobserved is None or bare.unobserved.num_rows == 0


def test_dota_categories_that_are_no_road_users(tmp_path, site_map):
    """DOTA labels 15-18 categories; only small-vehicle and large-vehicle are road users. A plane
    and a storage tank (in DOTA's corner form) are skipped with a count, or kept as class other."""
    rows = ["frame,track_id,x1,y1,x2,y2,x3,y3,x4,y4,class,difficult"]
    for k in range(10):
        u = 100 + 2 * k
        rows.append(f"{k},car1,{u},100,{u + 36},100,{u + 36},114,{u},114,small-vehicle,0")
        rows.append(f"{k},p7,400,400,480,400,480,470,400,470,plane,0")
        rows.append(f"{k},t9,600,600,630,600,630,630,600,630,storage-tank,1")
    tracks = tmp_path / "tracks.csv"
    tracks.write_text("\n".join(rows) + "\n")
    wf = write_world_file(tmp_path / "o.tfw")
    opts = {"frame_rate": 20.0, "crs": SITE_CRS}
    with pytest.warns(UserWarning, match=r"skipped 2 tracks: 1 plane, 1 storage-tank \(no road user\)"):
        rec = convert("rotated-boxes", [tracks, wf], map_source=site_map, options=opts)
    assert rec.participants.column("class").to_pylist() == ["car"]
    rec = convert("rotated-boxes", [tracks, wf], map_source=site_map,
                  options={**opts, "keep_non_road_users": True})
    assert sorted(rec.participants.column("class").to_pylist()) == ["car", "other", "other"]
