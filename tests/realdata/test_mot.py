"""MOTChallenge ground truth other tools wrote (an excerpt of MOT17-09, tests/data/third_party):
a walking pedestrian, a reflection of one in a shop window and a static person. Only the pedestrian
is a road user; the others are skipped with a count, or kept with keep_non_road_users. The ground
homography is ours (MOT has no map): a camera 10 m behind the image's bottom edge, looking along
+x of the straight test map."""

from __future__ import annotations

import numpy as np
import pytest

from aveas_format.converters import convert

from helpers_common import STRAIGHT_MAP
from helpers_realdata import assert_plausible, assert_same_trajectories, error_codes, round_trips, third_party


def _landmarks(tmp_path):
    """Ground points of a 1920 x 1080 image: distance 7800 / (v - 300) m ahead, lateral offset
    growing with it (a plane homography), the image's centre column over y = -5.25."""
    rows = ["u,v,x,y"]
    for u in (0.0, 960.0, 1920.0):
        for v in (500.0, 700.0, 1080.0):
            d = 7800.0 / (v - 300.0)
            rows.append(f"{u},{v},{d},{-(u - 960.0) * d / 1400.0 - 5.25}")
    p = tmp_path / "landmarks.csv"
    p.write_text("\n".join(rows) + "\n")
    return p


@pytest.mark.parametrize("path", third_party("mot17_*.txt"))
def test_mot17_ground_truth(path, tmp_path):
    lines = [ln.split(",") for ln in path.read_text().splitlines()]
    tracks = {ln[1]: int(ln[7]) for ln in lines}
    assert sorted(tracks.values()) == [1, 7, 12]  # pedestrian, static person, reflection
    lm = _landmarks(tmp_path)
    opts = {"rate_hz": 30.0, "image_size": (1920, 1080)}
    with pytest.warns(UserWarning, match=r"skipped 2 tracks: 1 reflection, 1 static_person \(no road user\)"):
        rec = convert("infra-lwir", [path, lm], map_source=STRAIGHT_MAP, options=opts)
    assert rec.participants.column("source_id").to_pylist() == ["1"]
    assert rec.participants.column("class").to_pylist() == ["pedestrian"]
    assert rec.states.num_rows == sum(1 for ln in lines if ln[1] == "1")  # every frame of the track
    assert error_codes(rec) == set()
    assert_plausible(rec)
    speed = np.hypot(rec.states.column("vx").to_numpy(), rec.states.column("vy").to_numpy())
    assert np.median(speed) < 2.5  # walking
    for fmt, back in round_trips(rec, tmp_path).items():
        assert_same_trajectories(rec, back, f"{path.name} via {fmt}")
    rec = convert("infra-lwir", [path, lm], map_source=STRAIGHT_MAP,
                  options={**opts, "keep_non_road_users": True})
    got = dict(zip(rec.participants.column("source_id").to_pylist(), rec.participants.column("class").to_pylist()))
    assert got == {"1": "pedestrian", "49": "other", "62": "pedestrian"}
