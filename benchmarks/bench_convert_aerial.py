"""Converting aerial data: a highD-layout recording with 1M track rows (tracks.csv with all 25 highD
columns, tracksMeta, recordingMeta), converted including the built map and map referencing; next to
the baseline of reading the same tracks.csv with pandas in the same run. Also the rotated-box
converter on 1M boxes with a world file.

Target (issue 6): highD 1M rows <= 20 s on a 2-core machine.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

UPPER = (8.51, 12.59, 16.43)
LOWER = (21.00, 24.96, 28.74)
HIGHD_TRACKS = ["frame", "id", "x", "y", "width", "height", "xVelocity", "yVelocity", "xAcceleration",
                "yAcceleration", "frontSightDistance", "backSightDistance", "dhw", "thw", "ttc",
                "precedingXVelocity", "precedingId", "followingId", "leftPrecedingId",
                "leftAlongsideId", "leftFollowingId", "rightPrecedingId", "rightAlongsideId",
                "rightFollowingId", "laneId"]


def write_highd(folder: Path, n_rows: int = 1_000_000, seed: int = 0) -> Path:
    """A synthetic highD recording of about ``n_rows`` rows in the real CSV layout."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(seed)
    frames_per = 350  # ~14 s in view at 30 m/s over 420 m, 25 fps
    n_veh = max(1, n_rows // frames_per)
    vid = np.repeat(np.arange(1, n_veh + 1), frames_per)
    k = np.tile(np.arange(frames_per), n_veh)
    start = np.repeat(np.arange(n_veh) * 7, frames_per)          # a vehicle every 0.28 s
    direction = np.where(vid % 2 == 0, 1, 2)
    speed = np.repeat(rng.uniform(22.0, 38.0, n_veh), frames_per)
    lane = np.repeat(rng.integers(0, 2, n_veh), frames_per)
    truck = np.repeat(rng.random(n_veh) < 0.2, frames_per)
    length = np.where(truck, 14.0, 4.6)
    width = np.where(truck, 2.5, 1.9)
    t = k / 25.0
    xc = np.where(direction == 2, 5.0 + speed * t, 415.0 - speed * t) % 410.0 + 5.0
    up, lo = np.array(UPPER), np.array(LOWER)
    yc = np.where(direction == 1, (up[lane] + up[lane + 1]) / 2, (lo[lane] + lo[lane + 1]) / 2)
    yc = yc + 0.2 * np.sin(0.5 * t + vid)
    vx = np.where(direction == 2, speed, -speed)
    vy = 0.1 * np.cos(0.5 * t + vid)
    n = len(vid)
    cols = {
        "frame": (start + k + 1).astype(np.int64), "id": vid.astype(np.int64),
        "x": np.round(xc - length / 2, 2), "y": np.round(yc - width / 2, 2),
        "width": length, "height": width, "xVelocity": np.round(vx, 2), "yVelocity": np.round(vy, 2),
        "xAcceleration": np.zeros(n), "yAcceleration": np.round(-0.05 * np.sin(0.5 * t + vid), 2),
    }
    for c in HIGHD_TRACKS[10:-1]:
        cols[c] = np.zeros(n, np.int64) if c.endswith("Id") else np.zeros(n)
    cols["laneId"] = np.where(direction == 1, 2 + lane, 5 + lane).astype(np.int64)
    folder.mkdir(parents=True, exist_ok=True)
    tracks = folder / "01_tracks.csv"
    pacsv.write_csv(pa.table({c: cols[c] for c in HIGHD_TRACKS}), tracks,
                    pacsv.WriteOptions(quoting_style="none"))
    ids = np.arange(1, n_veh + 1)
    first = np.arange(n_veh) * frames_per
    meta = ["id,width,height,initialFrame,finalFrame,numFrames,class,drivingDirection,"
            "traveledDistance,minXVelocity,maxXVelocity,meanXVelocity,minDHW,minTHW,minTTC,"
            "numLaneChanges"]
    for i, f0 in zip(ids, first):
        meta.append(f"{i},{length[f0]},{width[f0]},{start[f0] + 1},{start[f0] + frames_per},"
                    f"{frames_per},{'Truck' if truck[f0] else 'Car'},{direction[f0]},400,0,0,0,-1,-1,"
                    "-1,0")
    (folder / "01_tracksMeta.csv").write_text("\n".join(meta) + "\n")
    (folder / "01_recordingMeta.csv").write_text(
        "id,frameRate,locationId,speedLimit,month,weekDay,startTime,duration,totalDrivenDistance,"
        "totalDrivenTime,numVehicles,numCars,numTrucks,upperLaneMarkings,lowerLaneMarkings\n"
        f"1,25,2,-1.00,09.2017,Wed,08:38,{(start.max() + frames_per) / 25.0},0,0,{n_veh},0,0,"
        f"{';'.join(map(str, UPPER))},{';'.join(map(str, LOWER))}\n")
    return tracks


def write_boxes(folder: Path, n_rows: int = 1_000_000, seed: int = 0) -> tuple[Path, Path, Path]:
    """1M rotated boxes (cx, cy, w, h, angle, class scores) on a north-up 0.125 m orthophoto."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    rng = np.random.default_rng(seed)
    frames_per = 400
    n_veh = max(1, n_rows // frames_per)
    vid = np.repeat(np.arange(n_veh), frames_per)
    k = np.tile(np.arange(frames_per), n_veh)
    speed = np.repeat(rng.uniform(15.0, 35.0, n_veh), frames_per)
    x = -190.0 + speed * k / 20.0 % 380.0
    y = np.repeat(-1.75 - 3.5 * rng.integers(0, 2, n_veh), frames_per)
    gsd = 0.125
    cols = {"frame": (k + vid * 5).astype(np.int64), "track_id": vid.astype(np.int64),
            "cx": (x + 200.0) / gsd + rng.normal(0, 1, len(x)), "cy": (20.0 - y) / gsd,
            "w": np.full(len(x), 4.5 / gsd), "h": np.full(len(x), 1.8 / gsd),
            "angle": rng.normal(0, 1.0, len(x)), "score_car": np.full(len(x), 0.9),
            "score_van": np.full(len(x), 0.1)}
    folder.mkdir(parents=True, exist_ok=True)
    tracks = folder / "boxes.csv"
    pacsv.write_csv(pa.table(cols), tracks, pacsv.WriteOptions(quoting_style="none"))
    wld = folder / "ortho.tfw"
    wld.write_text(f"{gsd}\n0\n0\n{-gsd}\n{-200 + gsd / 2}\n{20 - gsd / 2}\n")
    xodr = folder / "road.xodr"
    from aveas_format.opendrive.builder import straight_highway

    xodr.write_text(straight_highway(length=400.0, lanes_right=2, x0=-200.0, geo_reference=(
        "+proj=tmerc +lat_0=48.9 +lon_0=8.4 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs")))
    return tracks, wld, xodr


def main(n_rows: int = 1_000_000) -> list[dict]:
    import pandas as pd

    from aveas_format.converters import convert

    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-aerial-"))
    rows: list[dict] = []
    try:
        tracks = write_highd(tmp / "highd", n_rows)
        t0 = time.perf_counter()
        df = pd.read_csv(tracks)
        t_base = time.perf_counter() - t0
        t0 = time.perf_counter()
        rec = convert("highd", [tracks])
        t_conv = time.perf_counter() - t0
        n = rec.states.num_rows
        on_map = 1.0 - rec.states.column("road_id").null_count / n
        rows.append({"benchmark": "convert.highd", "rows": n, "seconds": round(t_conv, 3),
                     "rows_per_s": round(n / t_conv), "baseline_s": round(t_base, 3),
                     "speedup_vs_baseline": round(t_base / t_conv, 3),
                     "note": f"incl. map build + referencing ({100 * on_map:.1f} % on a lane); "
                             f"baseline: pandas.read_csv of tracks.csv ({len(df):,} rows); "
                             "target <= 20 s"})
        del df, rec
        boxes, wld, xodr = write_boxes(tmp / "boxes", n_rows)
        t0 = time.perf_counter()
        df = pd.read_csv(boxes)
        t_base = time.perf_counter() - t0
        t0 = time.perf_counter()
        rec = convert("rotated-boxes", [boxes, wld], map_source=xodr,
                      options={"frame_rate": 20.0, "crs": "+proj=tmerc +lat_0=48.9 +lon_0=8.4 +k=1 "
                               "+x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"})
        t_conv = time.perf_counter() - t0
        n = rec.states.num_rows
        rows.append({"benchmark": "convert.rotated_boxes", "rows": n, "seconds": round(t_conv, 3),
                     "rows_per_s": round(n / t_conv), "baseline_s": round(t_base, 3),
                     "speedup_vs_baseline": round(t_base / t_conv, 3),
                     "note": "incl. covariance propagation, velocity regression, referencing; "
                             "baseline: pandas.read_csv of the box table"})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    for r in main():
        print(r)
