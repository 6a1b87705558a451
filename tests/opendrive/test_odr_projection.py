"""World -> road: round trips on every real map, candidates, headings, tracks, folds, properties."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from helpers_opendrive import fixture_map, real_map

from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import curved_highway, straight_highway

TOL = 1e-6


def _round_trip(net, n, seed, drivable_only=True):
    smp = net.sample_lane_points(n, seed=seed, drivable_only=drivable_only)
    x, y, _, _ = net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    proj = net.world_to_road(x, y)
    tab = proj.table
    pt = tab["point"]
    same = (
        (tab["road_id"] == smp["road_id"][pt])
        & (np.abs(tab["s"] - smp["s"][pt]) <= TOL)
        & (np.abs(tab["t"] - smp["t"][pt]) <= TOL)
    )
    found = np.zeros(n, dtype=bool)
    found[pt[same]] = True
    lane_ok = np.zeros(n, dtype=bool)
    lane_ok[pt[same & (tab["lane_id"] == smp["lane_id"][pt])]] = True
    return smp, proj, found, lane_ok


def _assert_round_trip(net, n, seed):
    smp, proj, found, lane_ok = _round_trip(net, n, seed)
    bad = np.flatnonzero(~found)
    assert found.all(), (
        f"{len(bad)} of {n} points lost their road position, e.g. {[(smp['road_id'][i], smp['s'][i], smp['t'][i]) for i in bad[:3]]}"
    )
    assert lane_ok.all()
    # the primary candidate is the source unless the point lies on several roads
    single = proj.n_candidates == 1
    assert (proj.road_id[single] == smp["road_id"][single]).all()
    assert (proj.lane_id[single] == smp["lane_id"][single]).all()
    assert np.abs(proj.s[single] - smp["s"][single]).max(initial=0) <= TOL
    return proj


def test_round_trip_every_real_map(real_net):
    _assert_round_trip(real_net, 20_000, seed=1)


@pytest.mark.slow
def test_round_trip_every_real_map_100k(real_net):
    _assert_round_trip(real_net, 100_000, seed=7)


def test_round_trip_every_fixture_road(geom_net):
    proj = _assert_round_trip(geom_net, 5_000, seed=3)
    assert (proj.n_candidates >= 1).all()


@pytest.mark.realdata
def test_junction_overlaps_are_reported_as_candidates():
    net = real_map("opendrive-test-files__Town04.xodr")
    smp, proj, found, _ = _round_trip(net, 5_000, seed=11)
    multi = np.flatnonzero(proj.n_candidates > 1)
    assert 0.05 < len(multi) / len(smp["s"]) < 0.5
    i = int(multi[0])
    cands = proj.candidates(i)
    assert len(cands) == proj.n_candidates[i]
    assert cands[0]["road_id"] == proj.road_id[i] and cands[0]["s"] == proj.s[i]
    assert any(c["road_id"] == smp["road_id"][i] for c in cands)
    # every candidate maps back to the same world point
    rid = np.array([c["road_id"] for c in cands], dtype=object)
    x, y, _, _ = net.road_to_world(rid, [c["s"] for c in cands], [c["t"] for c in cands])
    x0, y0, _, _ = net.road_to_world(smp["road_id"][i], smp["s"][i], smp["t"][i])
    assert np.hypot(x - x0, y - y0).max() < TOL


def test_off_map_points(geom_net):
    proj = geom_net.world_to_road([5000.0, 50.0, 50.0], [5000.0, 30.0, -3.0])
    assert proj.road_id[0] is None and proj.road_id[1] is None
    assert proj.lane_id[0] == 0 and np.isnan(proj.s[0]) and np.isnan(proj.lane_offset[0])
    assert proj.n_candidates[:2].tolist() == [0, 0]
    assert proj.road_id[2] == "line" and proj.lane_id[2] == -1
    assert proj.s[2] == pytest.approx(50.0) and proj.t[2] == pytest.approx(-3.0)
    assert proj.lane_offset[2] == pytest.approx(-3.0 + 1.75)
    assert proj.lane_id.dtype == np.int16 and proj.road_id.dtype == object
    assert len(proj) == 3 and proj.on_road.tolist() == [False, False, True]


def test_empty_input(geom_net):
    proj = geom_net.world_to_road(np.zeros(0), np.zeros(0))
    assert len(proj) == 0


def test_relative_heading(geom_net):
    x, y, _, h = geom_net.road_to_world("arc", [30.0, 30.0], [-1.0, 1.5])
    proj = geom_net.world_to_road(x, y, heading=h + np.array([0.1, np.pi]))
    np.testing.assert_allclose(proj.rel_heading, [0.1, np.pi], atol=1e-9)
    np.testing.assert_allclose(proj.road_heading, h, atol=1e-12)
    assert np.isnan(geom_net.world_to_road(x, y).rel_heading).all()


def test_heading_picks_the_lane_direction():
    """On two overlapping one-way roads in opposite directions, heading decides the primary."""
    xml = """<OpenDRIVE><header revMajor="1" revMinor="6"/>
    <road id="a" length="100" junction="-1"><planView><geometry s="0" x="0" y="0" hdg="0" length="100"><line/></geometry></planView>
    <lanes><laneSection s="0"><center><lane id="0"/></center><right><lane id="-1" type="driving"><width sOffset="0" a="4"/></lane></right></laneSection></lanes></road>
    <road id="b" length="100" junction="-1"><planView><geometry s="0" x="100" y="-4" hdg="3.141592653589793" length="100"><line/></geometry></planView>
    <lanes><laneSection s="0"><center><lane id="0"/></center><right><lane id="-1" type="driving"><width sOffset="0" a="4"/></lane></right></laneSection></lanes></road>
    </OpenDRIVE>"""
    net = load_map(xml)
    proj = net.world_to_road([50.0, 50.0], [-2.0, -2.0], heading=[0.05, np.pi - 0.05])
    assert proj.n_candidates.tolist() == [2, 2]
    assert proj.road_id.tolist() == ["a", "b"]


def _junction_trajectory(net):
    """A path through a Town04 junction: incoming road -> connecting road -> outgoing road."""
    for j in net.junctions.values():
        for c in j.connections:
            conn = net.roads.get(c.connecting_road or "")
            if conn is None or c.contact_point != "start" or not c.lane_links:
                continue
            ll = c.lane_links[0]
            if ll.to_lane >= 0 or conn.successor is None or conn.successor.element_type != "road":
                continue
            inc = net.roads[c.incoming_road]
            if inc.successor is None or inc.successor.element_id != j.id:
                continue
            out = net.roads[conn.successor.element_id]
            if out.junction is not None or out.predecessor is None or out.predecessor.element_id != j.id:
                continue
            s_conn = np.linspace(0.2, conn.length - 0.2, 40)
            segs = [
                (inc.id, np.linspace(inc.length - 6.0, inc.length - 0.5, 6), ll.from_lane),
                (conn.id, s_conn, ll.to_lane),
                (out.id, np.linspace(0.5, 6.0, 6), -1),
            ]
            xs, ys, truth = [], [], []
            for rid, s, lane in segs:
                inner, outer = net.lane_borders(rid, s, lane)
                if np.isnan(inner).any():
                    break
                x, y, _, _ = net.road_to_world(rid, s, (inner + outer) / 2)
                xs.append(x)
                ys.append(y)
                truth += [rid] * len(s)
            else:
                x, y = np.concatenate(xs), np.concatenate(ys)
                proj = net.world_to_road(x, y)
                if (proj.n_candidates[6:46] > 1).sum() >= 10:
                    return x, y, np.array(truth, dtype=object), proj
    pytest.skip("no suitable junction path found")


@pytest.mark.realdata
def test_track_chooses_by_continuity():
    net = real_map("opendrive-test-files__Town04.xodr")
    x, y, truth, plain = _junction_trajectory(net)
    t = np.arange(len(x)) * 0.1
    perm = np.random.default_rng(0).permutation(len(x))  # input order must not matter
    track = net.world_to_road_track(x[perm], y[perm], time=t[perm])
    chosen = np.empty(len(x), dtype=object)
    chosen[perm] = track.road_id
    on_truth = np.array([truth[i] in {c["road_id"] for c in plain.candidates(i)} for i in range(len(x))])
    assert on_truth.all()
    assert (chosen == truth).mean() == 1.0
    # the continuity choice is at least as good as the per-point one
    assert (chosen == truth).sum() >= (plain.road_id == truth).sum()


def test_track_with_several_tracks():
    net = load_map(straight_highway(length=300.0, lanes_right=2, lanes_left=2))
    x = np.r_[np.linspace(10, 200, 20), np.linspace(200, 10, 20)]
    y = np.r_[np.full(20, -1.75), np.full(20, 1.75)]
    proj = net.world_to_road_track(
        x, y, heading=np.r_[np.zeros(20), np.full(20, np.pi)], track_id=np.r_[np.zeros(20), np.ones(20)]
    )
    assert proj.lane_id.tolist() == [-1] * 20 + [1] * 20
    np.testing.assert_allclose(proj.s, x, atol=1e-9)


def test_fold_is_flagged():
    xml = """<OpenDRIVE><header revMajor="1" revMinor="6"/><road id="f" length="15" junction="-1"><planView>
    <geometry s="0" x="0" y="0" hdg="0" length="15"><arc curvature="0.3"/></geometry></planView>
    <lanes><laneSection s="0"><left><lane id="1" type="driving"><width sOffset="0" a="5"/></lane></left><center><lane id="0"/></center>
    <right><lane id="-1" type="driving"><width sOffset="0" a="3"/></lane></right></laneSection></lanes></road></OpenDRIVE>"""
    net = load_map(xml)
    x, y, _, _ = net.road_to_world("f", [5.0, 5.0], [4.0, -1.0])
    proj = net.world_to_road(x, y)
    assert proj.fold.tolist() == [True, False]
    c = proj.candidates(0)[0]
    assert c["s"] == pytest.approx(5.0) and c["t"] == pytest.approx(4.0) and c["fold"]
    assert "lane.fold" in {f.code for f in net.check()}


def test_drivable_only(geom_net):
    x, y, _, _ = geom_net.road_to_world("line", [50.0], [-8.0])  # on the sidewalk
    assert geom_net.world_to_road(x, y).lane_id.tolist() == [-3]
    assert geom_net.world_to_road(x, y, drivable_only=True).road_id.tolist() == [None]


def test_gap_between_geometries_is_bridged():
    net = fixture_map("quirks.xodr")  # a 2 cm gap between x = 100 and x = 100.02
    proj = net.world_to_road([100.01, 99.0], [-1.0, -1.0])
    assert proj.road_id.tolist() == ["7", "7"]
    assert proj.s[0] == pytest.approx(100.0) and proj.t[0] == pytest.approx(-1.0)


@pytest.mark.realdata
def test_threads_and_batches_agree():
    net = real_map("opendrive-test-files__Town03.xodr")
    smp = net.sample_lane_points(3000, seed=5)
    x, y, _, _ = net.road_to_world(smp["road_id"], smp["s"], smp["t"])
    a = net.world_to_road(x, y, threads=1, batch=1 << 20)
    b = net.world_to_road(x, y, threads=2, batch=500)
    assert (a.road_id == b.road_id).all() and np.array_equal(a.s, b.s) and (a.n_candidates == b.n_candidates).all()


@settings(max_examples=25, deadline=None)
@given(
    radius=st.floats(60.0, 3000.0) | st.floats(-3000.0, -60.0),
    spiral=st.floats(0.0, 50.0),
    hdg=st.floats(-np.pi, np.pi),
    lanes=st.tuples(st.integers(0, 3), st.integers(1, 4)),
    width=st.floats(2.5, 4.5),
    u=st.lists(st.tuples(st.floats(0.0, 1.0), st.floats(0.02, 0.98), st.integers(0, 100)), min_size=1, max_size=20),
)
def test_property_road_world_road(radius, spiral, hdg, lanes, width, u):
    left, right = lanes
    net = load_map(
        curved_highway(
            length=300.0,
            radius=radius,
            straight=20.0,
            spiral=spiral,
            lanes_left=left,
            lanes_right=right,
            lane_width=width,
            hdg=hdg,
            x0=1e3,
            y0=-2e3,
        )
    )
    n = left + right
    s = np.array([a for a, _, _ in u]) * 300.0
    lane_pick = np.array([k % n for _, _, k in u])
    frac = np.array([f for _, f, _ in u])
    lane_id = np.where(lane_pick < left, lane_pick + 1, -(lane_pick - left + 1))
    t = np.where(lane_id > 0, (lane_id - 1 + frac) * width, -(-lane_id - 1 + frac) * width)
    x, y, _, _ = net.road_to_world("1", s, t)
    proj = net.world_to_road(x, y)
    assert (proj.n_candidates >= 1).all()
    np.testing.assert_allclose(proj.s, s, atol=TOL)
    np.testing.assert_allclose(proj.t, t, atol=TOL)
    assert proj.lane_id.tolist() == lane_id.tolist()
    x2, y2, _, _ = net.road_to_world(proj.road_id, proj.s, proj.t)
    assert np.hypot(x2 - x, y2 - y).max() <= TOL


@settings(max_examples=25, deadline=None)
@given(
    road=st.sampled_from(
        [
            "line",
            "arc",
            "spiral",
            "spiral_flat",
            "spiral_tiny",
            "poly3",
            "ppoly_arclength",
            "ppoly_normalized",
            "border",
            "sections",
        ]
    ),
    a=st.floats(0, 1),
    b=st.floats(0.02, 0.98),
)
def test_property_fixture_roads(road, a, b):
    net = fixture_map("geometry_types.xodr")
    L = net.roads[road].length
    s = np.array([a * L])
    # a point across the whole road surface at s
    pieces = net.lanes.find_piece(np.array([net.road_index[road]]), s)
    tl, tr = net.lanes.extent(net.lanes.borders(pieces, s))
    t = tr + b * (tl - tr)
    x, y, _, _ = net.road_to_world(road, s, t)
    proj = net.world_to_road(x, y)
    cands = proj.candidates(0)
    assert any(c["road_id"] == road and abs(c["s"] - s[0]) <= TOL and abs(c["t"] - t[0]) <= TOL for c in cands)


def test_lane_type_lookup():
    from helpers_opendrive import fixture_map

    net = fixture_map("geometry_types.xodr")
    rid = next(iter(net.roads))
    road = net.roads[rid]
    sec = road.lane_sections[0]
    lane = next(iter(sec.right or sec.left))
    s = np.array([sec.s + 0.01])
    assert net.lane_type(rid, s, np.array([lane.id]))[0] == lane.type
    assert net.lane_type(rid, s, np.array([99]))[0] is None
