"""Lane leaders and followers across diverges and merges (resolved from each participant's own
route), and the lead and lag in the adjacent lanes, on small hand-made junction maps."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from aveas_format.derive import derive
from aveas_format.derive.interactions import lane_graph
from aveas_format.mapref.build import build_recording
from aveas_format.opendrive import load_map
from aveas_format.opendrive.builder import roads_xodr
from aveas_format.opendrive.model import (Connection, Geometry, Junction, Lane, LaneLink,
                                          LaneSection, Road, RoadLink)
from aveas_format.sample import SITE_CRS

from helpers_derive import recording, row

W = 3.5  # lane width
L = 4.0  # vehicle length


def _road(rid: str, x: float, y: float, hdg: float, length: float, *, curvature: float = 0.0,
          junction: str | None = None, pred: RoadLink | None = None,
          succ: RoadLink | None = None, lanes: int = 1) -> Road:
    """A road with right lanes -1..-lanes (driving along +s), each linked to the lane of the
    same id on the linked roads."""
    kind, params = ("arc", {"curvature": curvature}) if curvature else ("line", {})
    right = [Lane(id=-k, type="driving", widths=np.array([[0.0, W, 0.0, 0.0, 0.0]]),
                  predecessors=[-k] if pred is not None and pred.element_type == "road" else [],
                  successors=[-k] if succ is not None and succ.element_type == "road" else [])
             for k in range(1, lanes + 1)]
    return Road(id=rid, length=length, junction=junction, predecessor=pred, successor=succ,
                geometries=[Geometry(s=0.0, x=x, y=y, hdg=hdg, length=length, kind=kind,
                                     params=params)],
                lane_sections=[LaneSection(s=0.0, left=[], center=Lane(id=0), right=right)])


def _connection(cid: str, incoming: str, connecting: str) -> Connection:
    return Connection(id=cid, incoming_road=incoming, connecting_road=connecting,
                      contact_point="start", lane_links=[LaneLink(from_lane=-1, to_lane=-1)])


def _arc_end(x, y, h, k, length):
    return (x + (np.sin(h + k * length) - np.sin(h)) / k,
            y - (np.cos(h + k * length) - np.cos(h)) / k, h + k * length)


def diverge_map(straight_lanes: int = 1) -> str:
    """Road 1 (100 m, east) splits in junction J1: connecting road 10 (straight, 20 m) leads to
    road 2 (straight on), connecting road 11 (20 m arc to the right) to road 3. Roads 10 and 2
    have ``straight_lanes`` lanes; road 1's lane -1 leads into lane -1 of both branches."""
    k = -0.02
    x3, y3, h3 = _arc_end(100.0, 0.0, 0.0, k, 20.0)
    roads = [
        _road("1", 0.0, 0.0, 0.0, 100.0, succ=RoadLink("junction", "J1")),
        _road("10", 100.0, 0.0, 0.0, 20.0, junction="J1", pred=RoadLink("road", "1", "end"),
              succ=RoadLink("road", "2", "start"), lanes=straight_lanes),
        _road("11", 100.0, 0.0, 0.0, 20.0, curvature=k, junction="J1",
              pred=RoadLink("road", "1", "end"), succ=RoadLink("road", "3", "start")),
        _road("2", 120.0, 0.0, 0.0, 100.0, pred=RoadLink("junction", "J1"), lanes=straight_lanes),
        _road("3", x3, y3, h3, 100.0, pred=RoadLink("junction", "J1")),
    ]
    junction = Junction(id="J1", connections=[_connection("0", "1", "10"),
                                              _connection("1", "1", "11")])
    return roads_xodr(roads, [junction], name="diverge", geo_reference=SITE_CRS)


def merge_map() -> str:
    """Road 4 (100 m, east) and road 5 (100 m, from the north-west) merge in junction J2:
    connecting road 12 (straight, 20 m) and connecting road 13 (20 m arc to the left) both lead
    into road 6 (east, from (100, 0))."""
    k, h0 = 0.02, -0.4
    x13 = 100.0 + np.sin(h0) / k
    y13 = (1.0 - np.cos(h0)) / k
    roads = [
        _road("4", -20.0, 0.0, 0.0, 100.0, succ=RoadLink("junction", "J2")),
        _road("5", x13 - 100.0 * np.cos(h0), y13 - 100.0 * np.sin(h0), h0, 100.0,
              succ=RoadLink("junction", "J2")),
        _road("12", 80.0, 0.0, 0.0, 20.0, junction="J2", pred=RoadLink("road", "4", "end"),
              succ=RoadLink("road", "6", "start")),
        _road("13", x13, y13, h0, 20.0, curvature=k, junction="J2",
              pred=RoadLink("road", "5", "end"), succ=RoadLink("road", "6", "start")),
        _road("6", 100.0, 0.0, 0.0, 200.0, pred=RoadLink("junction", "J2")),
    ]
    junction = Junction(id="J2", connections=[_connection("0", "4", "12"),
                                              _connection("1", "5", "13")])
    return roads_xodr(roads, [junction], name="merge", geo_reference=SITE_CRS)


def drive(xodr: str, actors: list[dict], *, duration: float = 2.0, dt: float = 0.1):
    """A recording of actors driving along a list of roads at constant speed, with road
    coordinates given (not map-matched). Each actor: ``route`` (road ids), ``d`` (distance from
    the start of the route's first road at t = 0), ``v`` and optionally ``until`` (its last
    sample time) and ``lanes`` (its lane on each road of the route; -1 by default)."""
    net = load_map(xodr)
    cols: dict[str, list] = {k: [] for k in ("participant_id", "time", "x", "y", "heading", "vx",
                                             "vy", "road_id", "lane_id", "road_s", "road_t")}
    t_all = np.arange(int(round(duration / dt)) + 1) * dt
    for i, a in enumerate(actors):
        t = t_all[t_all <= a.get("until", duration) + 1e-9]
        d = a["d"] + a["v"] * t
        lengths = np.array([net.roads[r].length for r in a["route"]])
        start = np.r_[0.0, np.cumsum(lengths)[:-1]]
        k = np.clip(np.searchsorted(start, d, side="right") - 1, 0, len(lengths) - 1)
        s = d - start[k]
        assert (s <= lengths[k]).all(), "route too short"
        rid = np.array(a["route"], dtype=object)[k]
        lid = np.array(a.get("lanes", [-1] * len(lengths)))[k]
        tt = (lid + 0.5) * W  # lane centre offset (right lanes, constant width)
        x, y, h = np.zeros(len(t)), np.zeros(len(t)), np.zeros(len(t))
        for r in set(rid):
            m = rid == r
            xr, yr, hr, _ = net.reference_line(r, s[m])
            x[m] = xr - tt[m] * np.sin(hr)
            y[m] = yr + tt[m] * np.cos(hr)
            h[m] = hr
        cols["participant_id"].append(np.full(len(t), i))
        cols["time"].append(t)
        cols["x"].append(x)
        cols["y"].append(y)
        cols["heading"].append(h)
        cols["vx"].append(a["v"] * np.cos(h))
        cols["vy"].append(a["v"] * np.sin(h))
        cols["road_id"].append(rid.astype(str))
        cols["lane_id"].append(lid)
        cols["road_s"].append(s)
        cols["road_t"].append(tt)
    states = {k: np.concatenate(v) for k, v in cols.items()}
    states["road_id"] = list(states["road_id"])
    n = len(actors)
    return build_recording(
        map_source=xodr, method="aerial", partner="test", reference=False,
        participants={"participant_id": np.arange(n), "class": ["car"] * n,
                      "length": np.full(n, L), "width": np.full(n, 1.8)},
        states=states)


def _rel(rec, pid, relation, time=0.0):
    return {r["other_id"]: r for r in row(rec.derived["interactions"], participant_id=pid,
                                          time=time, relation=relation)}


# --- the lane graph ---------------------------------------------------------------------------------

def test_lane_graph_diverge_and_merge():
    g = lane_graph(load_map(diverge_map()))
    c = {k[0]: v[0] for k, v in g.chains.items()}
    assert c["10"] == c["2"] and c["11"] == c["3"]  # unique continuations chain
    assert len({c["1"], c["10"], c["11"]}) == 3
    assert sorted(x for x, _ in g.succ[c["1"]]) == sorted([c["10"], c["11"]])
    assert g.length[c["10"]] == pytest.approx(120.0)
    g = lane_graph(load_map(merge_map()))
    c = {k[0]: v[0] for k, v in g.chains.items()}
    assert c["4"] == c["12"] and c["5"] == c["13"] and c["6"] not in (c["4"], c["5"])
    assert g.succ[c["4"]] == [(c["6"], 0.0)] and g.succ[c["5"]] == [(c["6"], 0.0)]
    assert sorted(g.pred[c["6"]]) == sorted([c["4"], c["5"]])


# --- diverge: the participant's own route decides ---------------------------------------------------

def _diverge(route_a: list[str], until_a: float = 2.0):
    """A on road 1 at s = 85 (20 m/s); B on branch 11 at s = 5 (nearer), C on branch 10 at
    s = 15, both 20 m/s."""
    return drive(diverge_map(), [
        {"route": route_a, "d": 85.0, "v": 20.0, "until": until_a},
        {"route": ["11", "3"], "d": 5.0, "v": 20.0},
        {"route": ["10", "2"], "d": 15.0, "v": 20.0},
    ])


def test_diverge_leader_follows_own_route_straight():
    rec = _diverge(["1", "10", "2"])
    derive(rec, only="interactions", box_2d=False)
    lead = _rel(rec, 0, "leader")
    assert list(lead) == [2]  # C on its route, not the nearer B on the other branch
    assert lead[2]["gap"] == pytest.approx((100 - 85) + 15 - L, abs=1e-9)
    assert lead[2]["dhw"] == pytest.approx(lead[2]["gap"] + L, abs=1e-9)
    assert lead[2]["ttc"] is None and lead[2]["closing_speed"] == pytest.approx(0.0, abs=1e-9)
    assert list(_rel(rec, 2, "follower")) == [0]
    assert _rel(rec, 1, "follower") == {}
    # once on the connecting road, C is in A's own chain
    assert list(_rel(rec, 0, "leader", time=1.0)) == [2]


def test_diverge_leader_follows_own_route_right():
    rec = _diverge(["1", "11", "3"])
    derive(rec, only="interactions", box_2d=False)
    lead = _rel(rec, 0, "leader")
    assert list(lead) == [1]
    # B is 5 m (in s) into the right-turn connecting road (curvature -0.02): its lane centre, 1.75 m
    # right of the reference line, is on the inside of the turn, so gaps along it are (1 - 0.035)
    # times the distance in s (the lane centre's own arc length, not the reference line's)
    assert lead[1]["gap"] == pytest.approx((100 - 85) + 5 * (1 - 0.02 * 1.75) - L, abs=1e-6)
    assert list(_rel(rec, 1, "follower")) == [0] and _rel(rec, 2, "follower") == {}


def test_diverge_unknown_route_takes_nearest():
    """A's samples end before the junction: its route is unknown, all branches are searched and
    the nearest vehicle (B, 5 m into its branch) leads."""
    rec = _diverge(["1"], until_a=0.5)
    derive(rec, only="interactions", box_2d=False)
    assert list(_rel(rec, 0, "leader")) == [1]
    assert list(_rel(rec, 0, "leader", time=0.5)) == [1]


def test_diverge_route_by_road_when_the_lane_differs():
    """A's later samples are on the straight branch but in its lane -2 (not the continuation of
    A's lane): the road tells the branch, so C (on it) leads rather than the nearer B."""
    rec = drive(diverge_map(straight_lanes=2), [
        {"route": ["1", "10", "2"], "lanes": [-1, -2, -2], "d": 85.0, "v": 20.0},
        {"route": ["11", "3"], "d": 5.0, "v": 20.0},
        {"route": ["10", "2"], "d": 15.0, "v": 20.0},
    ])
    derive(rec, only="interactions", box_2d=False)
    assert list(_rel(rec, 0, "leader")) == [2]


def test_route_range_limits_the_search():
    rec = _diverge(["1", "10", "2"])
    derive(rec, only="interactions", box_2d=False, route_range=10.0)
    assert _rel(rec, 0, "leader") == {}  # C is 30 m beyond the end of A's chain


# --- merge: leaders past the merge point, followers from both approaches --------------------------

def test_merge_leader_and_followers_from_both_lanes():
    rec = drive(merge_map(), [
        {"route": ["4", "12", "6"], "d": 90.0, "v": 15.0},   # A1, 30 m before road 6
        {"route": ["5", "13", "6"], "d": 95.0, "v": 15.0},   # A2, 25 m before road 6
        {"route": ["6"], "d": 10.0, "v": 15.0},               # B, past the merge point
    ])
    derive(rec, only="interactions", box_2d=False)
    l1, l2 = _rel(rec, 0, "leader"), _rel(rec, 1, "leader")
    assert list(l1) == [2] and list(l2) == [2]
    assert l1[2]["gap"] == pytest.approx(30 + 10 - L, abs=1e-9)
    # A2's lane on the left-turn connecting road 13 (20 m in s, curvature +0.02) is on the outside
    # of the turn: its centre is 20 * (1 + 0.02 * 1.75) = 20.7 m long
    assert l2[2]["gap"] == pytest.approx(5 + 20 * (1 + 0.02 * 1.75) + 10 - L, abs=1e-6)
    fol = _rel(rec, 2, "follower")
    assert sorted(fol) == [0, 1]  # one follower per approaching lane
    assert fol[0]["gap"] == pytest.approx(l1[2]["gap"]) and fol[1]["gap"] == pytest.approx(
        l2[2]["gap"])
    # a vehicle on the connecting road is A1's leader (same chain) and follows B itself
    rec = drive(merge_map(), [
        {"route": ["4", "12", "6"], "d": 90.0, "v": 15.0},
        {"route": ["12", "6"], "d": 5.0, "v": 15.0},
        {"route": ["6"], "d": 10.0, "v": 15.0},
    ])
    derive(rec, only="interactions", box_2d=False)
    assert list(_rel(rec, 0, "leader")) == [1] and list(_rel(rec, 1, "leader")) == [2]
    assert list(_rel(rec, 2, "follower")) == [1]


# --- neighbours: lead and lag ------------------------------------------------------------------------

def test_neighbour_lead_and_lag():
    """Ego in lane -2 (y = -5.25); lane -1 (left of it): one car 20 m ahead, one 12 m behind
    and one 60 m behind (not the nearest); lane -3 (right): one car 30 m ahead only."""
    cars = [(100.0, -5.25), (120.0, -1.75), (88.0, -1.75), (40.0, -1.75), (130.0, -8.75)]
    rec = recording([{"x": x, "y": y, "length": L, "width": 1.8, "vx": 20.0, "vy": 0.0}
                     for x, y in cars])
    derive(rec, only="interactions", box_2d=False)
    left, right = _rel(rec, 0, "left_neighbour"), _rel(rec, 0, "right_neighbour")
    assert sorted(left) == [1, 2] and list(right) == [4]
    assert left[1]["dhw"] == pytest.approx(20.0, abs=1e-9)  # lead: front ahead, dhw > 0
    assert left[2]["dhw"] == pytest.approx(-12.0, abs=1e-9)  # lag: dhw < 0
    assert left[1]["gap"] == pytest.approx(20.0 - L, abs=1e-9)
    assert left[2]["gap"] == pytest.approx(12.0 - L, abs=1e-9)
    assert right[4]["dhw"] == pytest.approx(30.0, abs=1e-9)
    # the left lane's cars see the ego on their right: lag for the one ahead, lead for the others
    assert _rel(rec, 1, "right_neighbour")[0]["dhw"] == pytest.approx(-20.0, abs=1e-9)
    assert _rel(rec, 2, "right_neighbour")[0]["dhw"] == pytest.approx(12.0, abs=1e-9)
    assert _rel(rec, 3, "right_neighbour")[0]["dhw"] == pytest.approx(60.0, abs=1e-9)
    derive(rec, only="interactions", box_2d=False, neighbour_range=50.0)
    assert _rel(rec, 3, "right_neighbour") == {}


def test_neighbours_across_lane_sections():
    """The adjacent lane is followed along its chain: a car just past a lane-section boundary is
    the lead of a car just before it in the next lane (two lanes, sections at s = 0 and 50)."""
    def lanes():
        return [Lane(id=-k, type="driving", widths=np.array([[0.0, W, 0.0, 0.0, 0.0]]))
                for k in (1, 2)]

    road = Road(id="1", length=100.0,
                geometries=[Geometry(s=0.0, x=0.0, y=0.0, hdg=0.0, length=100.0, kind="line")],
                lane_sections=[LaneSection(s=0.0, center=Lane(id=0), right=lanes()),
                               LaneSection(s=50.0, center=Lane(id=0), right=lanes())])
    xodr = roads_xodr([road], name="sections", geo_reference=SITE_CRS)
    rec = recording([{"x": 45.0, "y": -5.25, "length": L, "width": 1.8, "vx": 10.0, "vy": 0.0},
                     {"x": 55.0, "y": -1.75, "length": L, "width": 1.8, "vx": 10.0, "vy": 0.0}],
                    xodr=xodr, duration=0.2)
    derive(rec, only="interactions", box_2d=False)
    lead = _rel(rec, 0, "left_neighbour")
    assert list(lead) == [1] and lead[1]["dhw"] == pytest.approx(10.0, abs=1e-9)
    assert _rel(rec, 1, "right_neighbour")[0]["dhw"] == pytest.approx(-10.0, abs=1e-9)


@pytest.mark.parametrize("route", [["1", "10", "2"], ["1", "11", "3"]])
def test_core_time_steps_follow_the_route_from_later_states(route):
    """``interactions.compute(core=(t0, t1))`` (a time window, derive.streamed): the rows of the
    core's time steps only, the same as deriving at once; the later states still choose the
    branch at the diverge (A is before it in the core, on its branch only afterwards)."""
    from aveas_format.derive.interactions import InteractionsParams, compute

    rec = _diverge(route)
    p = InteractionsParams()
    whole = compute(rec, p)
    t = whole.column("time").to_numpy()
    for t0, t1 in ((0.0, 0.25), (0.25, 1.05), (1.05, 3.0)):
        part = compute(rec, p, core=(t0, t1))
        want = whole.filter(pa.array((t >= t0) & (t < t1)))
        assert part.num_rows == want.num_rows > 0
        assert part.equals(want), (t0, t1)
    lead = compute(rec, p, core=(0.0, 0.05)).to_pylist()
    assert {r["other_id"] for r in lead if r["participant_id"] == 0
            and r["relation"] == "leader"} == ({2} if route[1] == "10" else {1})


def test_relation_and_kind_codes_name_the_tables_categories():
    """The rows carry relations and TTC kinds as codes; their names are the table's categories
    (relations sorted: the table's order of rows of one pair and time)."""
    from aveas_format.derive.interactions._pairs import KIND_NAMES, REL_NAMES
    from aveas_format.schema.enums import Relation, TtcKind

    assert REL_NAMES == tuple(sorted(Relation.values()))
    assert set(KIND_NAMES) - {None} == set(TtcKind.values())
