"""Maps built from trajectories: a simulated network against netconvert's own OpenDRIVE of it,
a highD-like recording against its lane ids, and the `map build` command."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pytest
from helpers_mapbuild import driven, highd_like, lane_agreement, lane_centres, lane_counts, sumo_scene

from aveas_format.errors import MapError
from aveas_format.opendrive import load_map
from aveas_format.opendrive.roadfit.tracks import map_from_tracks


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    sc = sumo_scene(tmp_path_factory.mktemp("sumo"))
    built = map_from_tracks(sc.x, sc.y, sc.track, sc.time, heading=sc.heading)
    return sc, built, load_map(sc.truth)


def test_lane_centres_follow_the_truth_along_driven_paths(scene):
    sc, built, truth = scene
    net = built.network()
    x, y, h, _, _ = lane_centres(net)
    m = driven(x, y, sc.x, sc.y)
    pr = truth.world_to_road(x[m], y[m], h[m], drivable_only=True)
    assert (pr.n_candidates > 0).all()
    assert np.percentile(np.abs(pr.lane_offset), 95) <= 0.3


def test_lane_counts_per_direction_equal_the_truths_driven_lanes(scene):
    sc, built, truth = scene
    ours, theirs = lane_counts(built.network(), truth, sc.x, sc.y)
    assert len(ours) > 500
    assert (ours == theirs).mean() >= 0.99  # the few others lie where the dropped lane tapers
    assert {3, 2, 1} <= set(ours)  # the lane drop (3 -> 2) and the single-lane arms


def test_one_connecting_road_per_driven_turning_movement(scene):
    sc, built, truth = scene
    net = built.network()
    assert built.junctions == 1 and built.connecting_roads == len(sc.movements) == 12
    pairs = {(r.predecessor.element_id, r.successor.element_id) for r in net.roads.values() if r.junction}
    assert len(pairs) == 12  # twelve different (incoming road, outgoing road) pairs
    j = next(iter(net.junctions.values()))
    assert sorted(c.connecting_road for c in j.connections) == sorted(r.id for r in net.roads.values() if r.junction)
    assert [f.message for f in net.check() if f.severity == "error"] == []
    assert built.report["on_lane_share"] >= 0.99 and built.report["lateral_p95_m"] < 0.3


def test_highd_like_states_get_the_sources_lanes():
    d = highd_like(600, duration=600, seed=3)
    built = map_from_tracks(d["x"], d["y"], d["track"], d["time"], heading=d["heading"])
    net = built.network()
    assert built.roads == 2 and all(len(r.lane_sections[0].right) == 3 for r in net.roads.values())
    widths = [ln.widths[0, 1] for r in net.roads.values() for ln in r.lane_sections[0].right]
    np.testing.assert_allclose(widths, 3.5, atol=0.1)  # from the lane spacing
    assert lane_agreement(net, d) >= 0.99


def test_too_little_traffic_is_a_clear_error():
    with pytest.raises(MapError, match="too few moving vehicle points"):
        map_from_tracks(np.arange(10.0), np.zeros(10), np.zeros(10), np.arange(10.0))


def test_cli_builds_from_a_tracks_table_and_references_a_recording(tmp_path):
    from aveas_format.cli import main

    d = highd_like(200, duration=300, seed=5)
    csv = tmp_path / "tracks.csv"
    pcsv.write_csv(pa.table({"track_id": d["track"], "time": d["time"], "x": d["x"], "y": d["y"],
                             "heading": d["heading"]}), csv)
    out = tmp_path / "site.xodr"
    with pytest.raises(SystemExit) as e:
        main(["map", "build", str(csv), "-o", str(out), "--report", str(tmp_path / "r.json")])
    assert e.value.code == 0
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["roads"] == 2 and rep["lanes"] == 6 and rep["on_lane_share"] > 0.99
    # the output exists now: refused without --overwrite
    with pytest.raises(SystemExit) as e:
        main(["map", "build", str(csv), "-o", str(out)])
    assert e.value.code == 2
    # a recording: built and referenced against its new map
    import aveas_format
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=60, duration_s=40)
    src = tmp_path / "rec.aveas"
    rec.write(src)
    with pytest.raises(SystemExit) as e:
        main(["map", "build", str(src), "-o", str(tmp_path / "b.xodr"), "--reference", str(tmp_path / "ref.aveas")])
    assert e.value.code == 0
    ref = aveas_format.open(tmp_path / "ref.aveas")
    assert load_map(ref.map_source).header.geo_reference == rec.meta.crs
    lanes = ref.states.column("lane_id").to_numpy(zero_copy_only=False)
    assert (lanes != 0).mean() > 0.99
    report = aveas_format.validate(ref)
    assert [f for f in report.findings() if f.code.startswith("map.") and f.severity == "error"] == []
