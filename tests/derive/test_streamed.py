"""Every criticality measure by time window (aveas_format.derive.streamed) against deriving the
whole recording at once."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq
import pytest

from aveas_format.derive import derive
from aveas_format.derive.streamed import derive_by_windows, merge_summaries
from aveas_format.sample import highway_scene


@pytest.fixture(scope="module")
def whole_and_windows(tmp_path_factory):
    d = tmp_path_factory.mktemp("streamed")
    rec = highway_scene(n_vehicles=30, duration_s=24.0, seed=3)
    rec.write(d / "h.aveas")
    info = derive_by_windows(d / "h.aveas", d / "out", window_s=8.0, margin_s=4.0, workers=1)
    derive(rec, only=["kinematics", "interactions", "conflicts", "criticality_summary"])
    return rec, info, d / "out"


def _keyed(t: pa.Table, cols: list[str]) -> dict:
    d = t.select(["participant_id", "time", "other_id", "relation", *cols]).to_pylist()
    return {(r["participant_id"], round(r["time"], 6), r["other_id"], str(r["relation"])):
            r for r in d}


def test_windows_cover_every_row_once(whole_and_windows):
    rec, info, out = whole_and_windows
    assert info["windows"] == 3
    for name in ("kinematics", "interactions", "conflicts"):
        assert info[name] == rec.derived[name].num_rows, name
        parts = sorted((out / name).glob("part-*.parquet"))
        assert len(parts) == 3
        assert ds.dataset(out / name).count_rows() == rec.derived[name].num_rows


def test_ttc_as_in_one_piece(whole_and_windows):
    """The same pairs, and TTC within its std: the kinematics smoother sees each window's tracks
    (with the margin) only and chooses its jerk density per track window by maximum likelihood,
    so the smoothed speeds differ by millimetres per second (0.15 of their std, median); with the
    measured velocities (velocities="states") the rows are identical."""
    rec, _, out = whole_and_windows
    a = _keyed(rec.derived["interactions"], ["ttc", "ttc_std"])
    b = _keyed(ds.dataset(out / "interactions").to_table(), ["ttc", "ttc_std"])
    assert a.keys() == b.keys()
    x = np.array([(a[k]["ttc"], b[k]["ttc"], a[k]["ttc_std"]) for k in a
                  if a[k]["ttc"] is not None and b[k]["ttc"] is not None and a[k]["ttc_std"]])
    assert len(x) > 100
    z = np.abs(x[:, 0] - x[:, 1]) / x[:, 2]
    assert np.median(z) < 0.3 and np.quantile(z, 0.99) < 1.5, np.quantile(z, [0.5, 0.99])


def test_summary_merged_from_the_windows(whole_and_windows):
    rec, info, out = whole_and_windows
    s = pq.read_table(out / "criticality_summary.parquet").to_pylist()
    w = rec.derived["criticality_summary"].to_pylist()
    assert info["participants"] == sum(r["scope"] == "participant" for r in w)
    rs, rw = (next(r for r in t if r["scope"] == "recording") for t in (s, w))
    assert rs["duration_s"] == pytest.approx(rw["duration_s"], rel=1e-6)
    assert rs["min_ttc"] == pytest.approx(rw["min_ttc"], rel=0.02)
    assert rs["tet"] == pytest.approx(rw["tet"], rel=0.05, abs=0.2)
    assert rs["ttc_samples_below"] == pytest.approx(rw["ttc_samples_below"], abs=5)


def test_merge_of_two_halves_by_hand():
    """Sums of time and TET (stds in quadrature), the minimum TTC with its pair, CPI weighted by
    time."""
    from aveas_format.derive.criticality import _table

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
        return _table(ids, out, counts, [[]], rv, [])

    m = merge_summaries([part(10.0, 1.0, 0.3, 2.0, 7, 0.1), part(30.0, 2.0, 0.4, 1.2, 9, 0.0)])
    r = next(r for r in m.to_pylist() if r["scope"] == "participant")
    assert r["duration_s"] == 40.0 and r["tet"] == 3.0
    assert r["tet_std"] == pytest.approx(0.5)
    assert (r["min_ttc"], r["min_ttc_other_id"]) == (1.2, 9)
    assert r["cpi"] == pytest.approx(1.0 / 40.0)
    assert r["ttc_samples_below"] == 6
    whole = next(r for r in m.to_pylist() if r["scope"] == "recording")
    assert whole["tet"] == 3.0 and whole["min_ttc"] == 1.2
