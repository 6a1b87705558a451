"""Conversion of a road-vehicle ROS 2 MCAP: 10 minutes at 10 Hz with 50 tracked objects.

The MCAP is generated here (``mcap_ros2.writer`` with the message definitions of
``../shared/data/ros2_msgdefs/``): ``autoware_perception_msgs/TrackedObjects`` (50 objects on a
3-lane road, poses/twists with covariance) and the ego's ``nav_msgs/Odometry``, 6,000 messages
each. Timed: ``convert("ros2-mcap", ...)`` (decode, frame changes with covariance propagation,
map referencing of 306,000 state rows, recording build). Baseline in the same run: only decoding
every message of the file with mcap_ros2's generic decoder (the converter decodes with rosbags'
generated deserialisers, which are faster).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
MSGDEFS = ROOT.parent / "shared" / "data" / "ros2_msgdefs"
GEO = "+proj=tmerc +lat_0=48.8 +lon_0=11.1 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def write_vehicle_mcap(path: Path, minutes: float = 10.0, rate: float = 10.0, n_obj: int = 50,
                       seed: int = 0) -> int:
    """Write the benchmark MCAP; returns the number of object samples."""
    from mcap_ros2.writer import Writer

    rng = np.random.default_rng(seed)
    n = int(minutes * 60 * rate)
    t0 = 1_700_000_000_000_000_000
    lane_y = np.array([-1.75, -5.25, -8.75])
    oy = lane_y[rng.integers(0, 3, n_obj)]
    ospeed = rng.uniform(20.0, 35.0, n_obj)
    ox0 = rng.uniform(-200.0, 400.0, n_obj)
    cov = np.zeros(36)
    cov[0], cov[1], cov[6], cov[7], cov[35] = 0.09, 0.02, 0.02, 0.04, 0.01
    tcov = np.zeros(36)
    tcov[0], tcov[7], tcov[35] = 0.25, 0.04, 0.01
    cov, tcov = cov.tolist(), tcov.tolist()
    zero3 = {"x": 0.0, "y": 0.0, "z": 0.0}
    uuids = [list(rng.integers(0, 256, 16).astype(int)) for _ in range(n_obj)]
    with open(path, "wb") as f:
        w = Writer(f)
        s_obj = w.register_msgdef("autoware_perception_msgs/msg/TrackedObjects",
                                  (MSGDEFS / "autoware_perception_msgs__TrackedObjects.msg").read_text())
        s_odo = w.register_msgdef("nav_msgs/msg/Odometry", (MSGDEFS / "nav_msgs__Odometry.msg").read_text())
        for i in range(n):
            t = i / rate
            t_ns = t0 + int(round(t * 1e9))
            stamp = {"sec": t_ns // 1_000_000_000, "nanosec": t_ns % 1_000_000_000}
            ex = 27.0 * t
            w.write_message("/localization/kinematic_state", s_odo, {
                "header": {"stamp": stamp, "frame_id": "map"}, "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": ex, "y": -5.25, "z": 0.0},
                                  "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                         "covariance": cov},
                "twist": {"twist": {"linear": {"x": 27.0, "y": 0.0, "z": 0.0}, "angular": zero3},
                          "covariance": tcov}}, log_time=t_ns)
            xs = ex + (ox0 + (ospeed - 27.0) * t) % 600.0 - 200.0
            objs = [{
                "object_id": {"uuid": uuids[k]}, "existence_probability": 0.99,
                "classification": [{"label": 1, "probability": 0.9}, {"label": 2, "probability": 0.1}],
                "kinematics": {
                    "pose_with_covariance": {"pose": {"position": {"x": float(xs[k]), "y": float(oy[k]), "z": 0.7},
                                                      "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                                             "covariance": cov},
                    "twist_with_covariance": {"twist": {"linear": {"x": float(ospeed[k]), "y": 0.0, "z": 0.0},
                                                        "angular": zero3}, "covariance": tcov},
                    "acceleration_with_covariance": {"accel": {"linear": zero3, "angular": zero3},
                                                     "covariance": [0.0] * 36},
                    "orientation_availability": 2, "is_stationary": False},
                "shape": {"type": 0, "footprint": {"points": []},
                          "dimensions": {"x": 4.5, "y": 1.8, "z": 1.5}}} for k in range(n_obj)]
            w.write_message("/perception/object_recognition/tracking/objects", s_obj,
                            {"header": {"stamp": stamp, "frame_id": "map"}, "objects": objs},
                            log_time=t_ns)
        w.finish()
    return n * n_obj


def _decode_all(path: Path) -> int:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    k = 0
    with open(path, "rb") as f:
        for _ in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            k += 1
    return k


def main(minutes: float = 10.0) -> list[dict]:
    from aveas_format.converters import convert, load_converters
    from aveas_format.opendrive.builder import straight_highway

    load_converters()  # imports outside the timing

    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-mcap-"))
    try:
        mcap = tmp / "vehicle.mcap"
        t0 = time.perf_counter()
        n_obj = write_vehicle_mcap(mcap, minutes=minutes)
        t_write = time.perf_counter() - t0
        xodr = tmp / "road.xodr"
        xodr.write_text(straight_highway(length=27.0 * minutes * 60 + 1000.0, lanes_right=3,
                                         x0=-400.0, geo_reference=GEO))
        t0 = time.perf_counter()
        n_msgs = _decode_all(mcap)
        t_decode = time.perf_counter() - t0
        t0 = time.perf_counter()
        rec = convert("ros2-mcap", [mcap], map_source=xodr)
        t_conv = time.perf_counter() - t0
        rows = rec.states.num_rows
        size = mcap.stat().st_size
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return [{
        "benchmark": "convert.ros2_mcap_10min", "rows": rows, "seconds": round(t_conv, 3),
        "rows_per_s": round(rows / t_conv), "baseline_s": round(t_decode, 3),
        "speedup_vs_baseline": round(t_decode / t_conv, 2),
        "note": (f"{n_msgs} messages ({n_obj} object samples, {size / 1e6:.1f} MB MCAP, written in "
                 f"{t_write:.1f} s); baseline = decoding every message with mcap_ros2 only"),
    }]


if __name__ == "__main__":
    for r in main():
        print(r)
