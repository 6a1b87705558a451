"""`aveas-format find ARCHIVE`: the most critical situations across recordings, cut out for
replay; the catalog's criticality columns; info's criticality table; the HTML report's section."""

from __future__ import annotations

import json
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.dataset.find import parse_where, rank, situations


def cli(*args):
    return subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                          capture_output=True, text=True, timeout=300)


def test_where_is_parsed_or_refused():
    assert parse_where("min_ttc < 1.5 and max_drac >= 3") == [("min_ttc", "<", 1.5),
                                                               ("max_drac", ">=", 3.0)]
    with pytest.raises(ValueError, match="unknown measure 'ttc'"):
        parse_where("ttc < 1")
    with pytest.raises(ValueError, match="cannot read"):
        parse_where("min_ttc <")


def test_find_ranks_across_recordings_and_cuts_out(dataset_root, tmp_path):
    paths = sorted(str(p) for p in dataset_root.rglob("*.aveas*") if "u1" not in p.name
                   and "v2" not in p.name)
    table, missing, failed = situations(paths)
    assert not missing and not failed and table.num_rows > 0
    top = rank(table, "min_ttc < 100", "min_ttc", 5)
    ttc = top.column("min_ttc").to_pylist()
    assert ttc == sorted(ttc) and len(ttc) <= 5
    res = cli("find", *paths, "--top", "2", "--format", "json", "--cut", tmp_path / "cuts")
    assert res.returncode == 0, res.stderr
    d = json.loads(res.stdout)
    assert d["recordings"] == len(paths) and d["matching"] == len(d["results"]) <= 2
    first = d["results"][0]
    assert first["min_ttc"] == pytest.approx(min(table.column("min_ttc").drop_null().to_pylist()))
    small, xosc = first["cut"][0], first["cut"][1]
    assert small.endswith(".aveas") and xosc.endswith(".xosc")
    rec = aveas_format.open(small)
    assert set(rec.participants.column("participant_id").to_pylist()) == {
        first["participant_id"], first["other_id"]}
    assert rec.map_source is not None and rec.states.column("time").to_pylist()[0] >= 0
    assert aveas_format.validate(small).counts["error"] == 0
    # text; recordings without a summary are named; cut-outs are not replaced silently
    res = cli("find", dataset_root, "--where", "min_ttc < 100", "--cut", tmp_path / "cuts",
              "--top", "1")
    assert res.returncode == 2 and "exists" in res.stderr  # the first cut exists
    res = cli("find", dataset_root, "--by", "max_drac")
    assert res.returncode == 0 and "most critical" in res.stdout
    assert "have no derived/criticality_summary" in res.stderr
    # every header whole, however narrow the pipe (rich cut them at 80 columns)
    assert "max DRAC m/s²" in res.stdout and "…" not in res.stdout
    assert cli("find", dataset_root, "--where", "nope > 1").returncode == 2
    assert cli("find", dataset_root, "--events", "--where", "min_ttc < 1").returncode == 2


def test_find_on_recordings_never_derived(dataset_root):
    """Issue 42: the hint, and no internal error, where no recording has a summary or events."""
    never = [str(dataset_root / "kit" / "u1.aveas"), str(dataset_root / "tub" / "v2.aveas")]
    for extra in ((), ("--events",)):
        res = cli("find", *never, *extra)
        assert res.returncode == 0, res.stderr
        assert "run aveas-format derive" in res.stderr and "Error" not in res.stderr
        assert "0 " in res.stdout.splitlines()[0]
        res = cli("find", *never, *extra, "--format", "json")
        assert res.returncode == 0 and json.loads(res.stdout)["results"] == []


def test_find_events_across_recordings(tmp_path):
    """--events: the derived conflicts of every recording, most likely to collide first, with a
    figure each."""
    from aveas_format.derive import derive
    from aveas_format.sample.scenes import conflict_scene

    paths = []
    for k, kind in enumerate(("cut_in", "crossing")):
        rec = conflict_scene(kind, 1.0, method="lidar", seed=k)
        derive(rec)
        paths.append(rec.write(tmp_path / f"{kind}.aveas"))
    res = cli("find", *paths, "--events", "--format", "json", "--figures", tmp_path / "figs")
    assert res.returncode == 0, res.stderr
    d = json.loads(res.stdout)
    assert d["events"] == 2 and len(d["results"]) == 2
    p = [r["collision_probability"] for r in d["results"]]
    assert p == sorted(p, reverse=True)
    assert all(r["kind"] == "conflict" and r["metric"] == "ttc" for r in d["results"])
    assert all((tmp_path / "figs").joinpath(r["figure"]).exists() for r in d["results"])
    res = cli("find", *paths, "--events", "--where", "collision_probability >= 0")
    assert res.returncode == 0 and "P(collision)" in res.stdout and "conflict" in res.stdout


def test_catalog_has_the_summary_columns(dataset_root, tmp_path):
    res = cli("catalog", dataset_root, "-o", tmp_path / "c.parquet", "--no-validate")
    assert res.returncode == 0, res.stderr
    t = pq.read_table(tmp_path / "c.parquet")
    rows = {r["path"].split("/")[-1]: r for r in t.to_pylist()}
    a1 = rows["a1.aveas"]
    assert a1["tet_s"] is not None and a1["max_drac_mps2"] is not None
    assert a1["min_ttc_std_s"] is not None and isinstance(a1["worst_events"], list)
    assert rows["u1.aveas"]["tet_s"] is None  # not derived


def test_info_and_report_show_the_criticality(dataset_root, tmp_path):
    path = dataset_root / "kit" / "a1.aveas"
    res = cli("info", path)
    assert res.returncode == 0 and "criticality (TTC threshold" in res.stdout
    assert "TET (s)" in res.stdout and "max DRAC" in res.stdout
    res = cli("validate", path, "--format", "html")
    assert res.returncode == 0 and "<h2>Criticality</h2>" in res.stdout
    assert "<h3>Worst events</h3>" in res.stdout and "CPI</span>" in res.stdout
