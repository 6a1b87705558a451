"""Every criticality measure by time window (aveas_format.derive.streamed) against deriving the
whole recording at once: the same tables (docs/derive.md "Large recordings")."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.derive import derive
from aveas_format.derive.registry import stale_derived
from aveas_format.derive.streamed import derive_by_windows, merge_summaries, write_by_windows
from aveas_format.sample import highway_scene
from aveas_format.sample.scenes import traffic_scene

WINDOWED = ["kinematics", "interactions", "conflicts", "criticality_summary"]


def with_crossers(rec, n: int = 6, speed: float = 4.0, seed: int = 0):
    """``rec`` plus ``n`` participants crossing the highway at right angles (northwards, at
    ``speed``), staggered so that their paths cross the vehicles' (crossing conflicts)."""
    rng = np.random.default_rng(seed)
    s, p = rec.states, rec.participants
    t_all = np.unique(s.column("time").to_numpy())
    first = int(p.column("participant_id").to_numpy().max()) + 1
    rows, parts = [], []
    for k in range(n):
        pid = first + k
        t = t_all[(t_all >= 1.0 + 3.5 * k) & (t_all <= 1.0 + 3.5 * k + 9.0)]
        y = -22.0 + speed * (t - t[0])
        x = np.full(len(t), 150.0 + 120.0 * k + rng.normal(0, 0.05, len(t)))
        rows.append(pa.table({"participant_id": np.full(len(t), pid, np.int64), "time": t,
                              "x": x, "x_std": np.full(len(t), 0.1), "y": y,
                              "y_std": np.full(len(t), 0.1),
                              "heading": np.full(len(t), np.pi / 2),
                              "heading_std": np.full(len(t), 0.02),
                              "vx": np.zeros(len(t)), "vx_std": np.full(len(t), 0.1),
                              "vy": np.full(len(t), speed), "vy_std": np.full(len(t), 0.1)}))
        parts.append(pid)
    extra = pa.concat_tables(rows)
    cols = {c: (extra.column(c) if c in extra.column_names else pa.nulls(extra.num_rows,
                                                                          s.schema.field(c).type))
            for c in s.column_names}
    rec.states = pa.concat_tables([s, pa.table(cols, schema=s.schema)])
    proto = p.slice(0, 1).to_pylist()[0]
    newp = [{**proto, "participant_id": pid, "source_id": f"crosser-{pid}"} for pid in parts]
    rec.participants = pa.concat_tables([p, pa.Table.from_pylist(newp, schema=p.schema)])
    return rec


@pytest.fixture(scope="module")
def whole_and_windows(tmp_path_factory):
    d = tmp_path_factory.mktemp("streamed")
    rec = with_crossers(highway_scene(n_vehicles=30, duration_s=24.0, seed=3))
    src = rec.write(d / "h.aveas")
    info = write_by_windows(src, d / "w.aveas.zip", window_s=8.0, workers=1)
    whole = aveas_format.open(src)
    derive(whole, only=WINDOWED)
    whole = aveas_format.open(whole.write(d / "whole.aveas"))  # as written
    return whole, aveas_format.open(d / "w.aveas.zip"), info, d


def _equal(a: pa.Table, b: pa.Table, name: str) -> None:
    assert a.column_names == b.column_names, name
    assert a.num_rows == b.num_rows, name
    for c in a.column_names:
        x, y = a.column(c), b.column(c)
        if pa.types.is_floating(x.type):
            x, y = (v.to_numpy(zero_copy_only=False) for v in (x, y))
            np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-12, err_msg=f"{name}.{c}")
        else:
            assert x.equals(y), f"{name}.{c}"


def test_every_table_as_derived_at_once(whole_and_windows):
    """Kinematics per chunk of whole tracks, the pairs and crossings of each window on the whole
    tracks of its participants (routes and crossing points ahead), the Monte Carlo std keyed by
    pair and time: the same rows and values as deriving the recording at once."""
    whole, win, info, _ = whole_and_windows
    assert info["windows"] == 3
    assert whole.derived["conflicts"].num_rows > 20  # the crossers' conflicts
    for name in ("kinematics", "interactions", "conflicts"):
        _equal(whole.derived[name], win.derived[name], name)


def test_summary_as_derived_at_once(whole_and_windows):
    """The summary merged from the windows: the same sums, minima and their pairs; the TET/TIT
    std (Monte Carlo per episode, an episode cut by a window boundary is two) within a tenth of
    the TET; min_pet and the event counts need encroachments and events (not by windows)."""
    whole, win, _, _ = whole_and_windows
    a, b = (t.derived["criticality_summary"] for t in (whole, win))
    skip = {"tet_std", "tit_std", "min_pet", "min_pet_std", "near_misses", "conflicts",
            "hard_braking", "worst_events"}
    keep = [c for c in a.column_names if c not in skip]
    _equal(a.select(keep), b.select(keep), "criticality_summary")
    np.testing.assert_allclose(b.column("tet_std").to_numpy(zero_copy_only=False),
                               a.column("tet_std").to_numpy(zero_copy_only=False),
                               atol=0.1 * max(pa.compute.max(a.column("tet")).as_py(), 1e-3))


def test_written_recording_is_valid_and_fresh(whole_and_windows):
    """The base tables are the source's bytes, the derived tables carry provenance like derive's
    (not stale); validate finds what it finds in the recording derived at once."""
    from aveas_format.validate import validate

    _, win, _, d = whole_and_windows
    assert stale_derived(win) == []
    assert {e.table for e in win.meta.derived} == {f"derived/{n}" for n in WINDOWED}
    src = aveas_format.open(d / "h.aveas")
    assert win.meta.tables["states"].sha256 == src.meta.tables["states"].sha256
    # the same findings as the recording derived at once (the crossers walk off the road)
    a, b = validate(d / "whole.aveas"), validate(d / "w.aveas.zip")
    assert b.counts["error"] == a.counts["error"]
    assert set(b.codes) == set(a.codes) - {"metadata.derived_stale"}


def test_parts_cover_every_row_once(tmp_path, whole_and_windows):
    whole, _, _, d = whole_and_windows
    info = derive_by_windows(d / "h.aveas", tmp_path / "out", window_s=8.0, workers=1)
    for name in ("kinematics", "interactions", "conflicts"):
        assert info[name] == whole.derived[name].num_rows, name
        assert ds.dataset(tmp_path / "out" / name).count_rows() == whole.derived[name].num_rows
    assert pq.read_table(tmp_path / "out" / "criticality_summary.parquet").num_rows == \
        whole.derived["criticality_summary"].num_rows


def test_merge_of_two_halves_by_hand():
    """Sums of time and TET (stds in quadrature), the minimum TTC with its pair, CPI weighted by
    time."""
    from aveas_format.derive.criticality import summary_table

    def part(dur, tet, tet_sd, mttc, other, cpi):
        ids = np.array([4], np.int64)
        nan = np.array([np.nan])
        out = {"duration_s": np.array([dur]), "tet": np.array([tet]), "tet_std": np.array([tet_sd]),
               "tit": np.array([0.0]), "tit_std": np.array([0.0]), "cpi": np.array([cpi]),
               "cpi_std": np.array([0.0]), "min_ttc": np.array([mttc]),
               "min_ttc_std": np.array([0.1]), "min_ttc_time": np.array([dur]),
               "min_ttc_other_id": np.array([other], np.int64),
               "min_ttc_kind": np.array(["lane_1d"], object), "max_drac": nan,
               "max_drac_std": nan, "min_psd": nan, "min_psd_std": nan, "min_pet": nan,
               "min_pet_std": nan, "ttc_samples_below": np.array([3], np.int64)}
        counts = {"near_misses": np.zeros(1, np.int64), "hard_braking": np.zeros(1, np.int64)}
        rv = {"duration_s": dur, "tet": tet, "tet_std": tet_sd, "tit": 0.0, "tit_std": 0.0,
              "cpi": cpi, "cpi_std": 0.0, "min_ttc": mttc, "min_ttc_std": 0.1,
              "min_ttc_time": dur, "min_ttc_other_id": other, "min_ttc_kind": "lane_1d",
              "max_drac": np.nan, "max_drac_std": np.nan, "min_psd": np.nan,
              "min_psd_std": np.nan, "min_pet": np.nan, "min_pet_std": np.nan,
              "ttc_samples_below": 3, "near_misses": 0, "hard_braking": 0}
        return summary_table(ids, out, counts, [[]], rv, [])

    m = merge_summaries([part(10.0, 1.0, 0.3, 2.0, 7, 0.1), part(30.0, 2.0, 0.4, 1.2, 9, 0.0)])
    r = next(r for r in m.to_pylist() if r["scope"] == "participant")
    assert r["duration_s"] == 40.0 and r["tet"] == 3.0
    assert r["tet_std"] == pytest.approx(0.5)
    assert (r["min_ttc"], r["min_ttc_other_id"]) == (1.2, 9)
    assert r["cpi"] == pytest.approx(1.0 / 40.0)
    assert r["ttc_samples_below"] == 6
    whole = next(r for r in m.to_pylist() if r["scope"] == "recording")
    assert whole["tet"] == 3.0 and whole["min_ttc"] == 1.2


# --- events by windows: against the truth and deriving at once ----------------------------------

EVENT_COLUMNS = ("kind", "participant_ids", "roles", "metric", "relation", "time_start",
                 "time_end", "time_extreme", "duration", "value", "value_std",
                 "collision_probability", "collision_probability_std", "confidence")


def _events_whole_and_windows(tmp_path, rec, window_s: float):
    src = rec.write(tmp_path / "s.aveas")
    whole = aveas_format.open(src)
    derive(whole, only=[*WINDOWED, "events"])
    write_by_windows(src, tmp_path / "w.aveas", window_s=window_s, workers=1)
    return whole, aveas_format.open(tmp_path / "w.aveas")


def _same(y, x, where: str) -> None:
    """``y`` equals ``x`` (numbers to 1e-9, nested in dicts and lists)."""
    if isinstance(x, dict):
        assert y.keys() == x.keys(), where
        for k in x:
            _same(y[k], x[k], f"{where}.{k}")
    elif isinstance(x, list):
        assert len(y) == len(x), where
        for i, (u, v) in enumerate(zip(y, x)):
            _same(u, v, f"{where}[{i}]")
    elif isinstance(x, float):
        assert y == pytest.approx(x, rel=1e-9, abs=1e-12), where
    else:
        assert y == x, where


def _derived_events(rec) -> list[dict]:
    ev = rec.events
    return [] if ev is None else [r for r in ev.to_pylist() if r["origin"] == "derived"]


@pytest.mark.parametrize("window_s", [15.0, 16.0])
def test_events_cut_by_windows_as_derived_at_once(tmp_path, window_s):
    """A cut-in (true minimum TTC 1.0 s) and a hard braking (1.3 s) on a motorway, in windows
    whose boundaries cut the encounters (15 s: the cut-in's first 0.08 s critical in one window,
    the rest in the next; the braking and its TTC encounter at 45 s; 16 s: the cut-in in the
    middle): the events are the truth's (pairs, minimum TTC within max(0.3 s, 20 %)) and the same
    as deriving at once — pairs, kinds, extremes, times, durations, collision probabilities —
    and so are the summary's event counts and worst events."""
    rec, truth = traffic_scene(60.0, conflicts=(("cut_in", 1.0), ("hard_braking", 1.3)), seed=2,
                               return_truth=True)
    whole, win = _events_whole_and_windows(tmp_path, rec, window_s)
    a, b = _derived_events(whole), _derived_events(win)
    crit = [e for e in b if e["kind"] in ("conflict", "near_miss")]
    assert sorted(tuple(sorted(e["participant_ids"])) for e in crit) == sorted(
        tuple(sorted(c["participants"])) for c in truth["conflicts"])
    for c in truth["conflicts"]:
        e = next(e for e in crit if set(e["participant_ids"]) == set(c["participants"]))
        assert abs(e["value"] - c["min_ttc"]) <= max(0.3, 0.2 * c["min_ttc"]), (e, c)
    # a boundary cuts an encounter (the test is about something)
    cuts = [k * window_s for k in range(1, int(60 // window_s) + 1)]
    assert any(e["time_start"] < c < e["time_end"] for e in crit for c in cuts)
    assert any(e["kind"] == "hard_braking" for e in b)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        for c in EVENT_COLUMNS:
            if isinstance(x[c], float):
                assert y[c] == pytest.approx(x[c], rel=1e-9, abs=1e-9), (c, x, y)
            else:
                assert y[c] == x[c], (c, x, y)
        ax, ay = json.loads(x["attributes"]), json.loads(y["attributes"])
        assert ax.keys() == ay.keys()
        for k in ax:
            if k != "cpi":  # of a joined episode: weighted by its pieces' durations
                _same(ay[k], ax[k], k)
    sa, sb = (t.derived["criticality_summary"].select(
        ["participant_id", "near_misses", "conflicts", "hard_braking", "worst_events"])
        for t in (whole, win))
    assert sb.equals(sa)
    assert stale_derived(win) == []


def test_no_events_in_noise_by_windows(tmp_path):
    """Lane-keeping traffic with the worst aerial noise (0.3 m) in 10-s windows: no conflict, no
    near miss, as deriving at once."""
    rec = traffic_scene(40.0, method="aerial", position_std=0.3, seed=11)
    whole, win = _events_whole_and_windows(tmp_path, rec, 10.0)
    assert [e for e in _derived_events(win) if e["kind"] != "hard_braking"] == []
    assert len(_derived_events(win)) == len(_derived_events(whole))
    r = next(r for r in win.derived["criticality_summary"].to_pylist()
             if r["scope"] == "recording")
    assert (r["near_misses"], r["conflicts"]) == (0, 0)
