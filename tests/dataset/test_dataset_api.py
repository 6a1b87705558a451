"""aveas_format.dataset: discovery, dataset validation with the local process pool, catalog and
dataset-wide statistics."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.dataset as pads
import pytest
import shapely

import aveas_format
from aveas_format import dataset as ds
from aveas_format.dataset import discovery
from aveas_format.errors import AveasError
from aveas_format.io import reader
from aveas_format.io.reader import open_recording

from helpers_dataset import validate_or_crash


def test_discover_directories_globs_lists_and_urls(dataset_root, tmp_path):
    found = ds.discover(dataset_root)
    assert [Path(p).relative_to(dataset_root).as_posix() for p in found] == [
        "kit/a1.aveas", "kit/a2.aveas.zip", "kit/u1.aveas", "tub/v1.aveas", "tub/v2.aveas"]
    # a recording is not searched inside; a recording given directly is itself
    assert ds.discover(dataset_root / "kit" / "a1.aveas") == [str(dataset_root / "kit" / "a1.aveas")]
    assert len(ds.discover(str(dataset_root / "*" / "*.aveas"))) == 4
    assert len(ds.discover(str(dataset_root / "**" / "*.zip"))) == 1
    # lists, duplicates removed
    assert len(ds.discover([dataset_root / "kit", dataset_root / "kit" / "a1.aveas"],
                           dataset_root / "tub")) == 5
    # file:// URLs through pyarrow.fs
    assert ds.discover(f"file://{dataset_root}") == [str(p) for p in found]
    # a missing path is kept (its task fails), an empty directory or glob is an error
    assert ds.discover(tmp_path / "missing.aveas") == [str(tmp_path / "missing.aveas")]
    (tmp_path / "empty").mkdir()
    with pytest.raises(AveasError, match="no recordings found"):
        ds.discover(tmp_path / "empty")
    with pytest.raises(AveasError, match="no recordings found"):
        ds.discover(str(tmp_path / "nothing-*.aveas"))
    # CLI arguments: one recording stays the single-recording mode
    assert not ds.is_dataset_spec([str(found[0])])
    assert not ds.is_dataset_spec(["does-not-exist.aveas"])
    assert ds.is_dataset_spec([str(dataset_root)])
    assert ds.is_dataset_spec([str(found[0]), str(found[1])])


def test_validate_dataset_with_the_process_pool(broken_dataset, tmp_path):
    paths = ds.discover(broken_dataset)
    seen = []
    rep = ds.validate_dataset(paths, workers=2, reports_dir=tmp_path / "reports",
                              on_result=seen.append)
    assert len(seen) == 6 and rep.recordings == 6
    # the file that is not a recording is reported with its error; the others complete
    assert [Path(f.path).name for f in rep.failed] == ["corrupt.aveas.zip"]
    assert "not a recording" in rep.failed[0].error
    assert len(rep.entries) == 5
    assert rep.exit_code() == 3
    # as Report: exit_code, counts, max_severity are properties; a frame of the recordings
    assert rep.exit_code == 3 and rep.max_severity.value == "error" and rep.counts["error"] >= 1
    assert repr(rep).startswith("<DatasetReport validate: 6 recordings, 4 valid, 1 failed; ")
    import pandas as pd

    df = rep.to_pandas()
    assert list(df["path"]) == sorted(paths) and len(df) == 6
    row = df.set_index(df["path"].map(lambda p: Path(p).name))
    assert row.loc["corrupt.aveas.zip", "status"] == "failed"
    assert row.loc["corrupt.aveas.zip", "error"] is pd.NA
    assert "not a recording" in row.loc["corrupt.aveas.zip", "failure"]
    assert row.loc["v2.aveas", "status"] == "findings" and row.loc["v2.aveas", "exit_code"] == 1
    assert row.loc["v2.aveas", "top_rule"] == "structure.row_count"
    assert row.loc["v2.aveas", "partner"] == "TUB" and str(df["error"].dtype) == "Int64"
    assert (df["status"] == "valid").sum() == 4
    d = json.loads(rep.to_json())
    assert d["by_rule"]["structure.row_count"] == {
        "severity": "error", "title": d["by_rule"]["structure.row_count"]["title"], "count": 1,
        "recordings": 1}
    assert d["by_partner"]["TUB"]["error"] >= 1 and d["by_partner"]["TUB"]["valid"] == 1
    assert d["by_partner"]["KIT"] | {"rules": {}} == {
        "recordings": 3, "failed": 0, "valid": 3, "error": 0, "warning": 0, "info": 0,
        "rules": {}}
    assert d["by_partner"]["(unknown)"]["failed"] == 1
    worst = [Path(w["path"]).name for w in d["worst"]]
    assert worst[:2] == ["corrupt.aveas.zip", "v2.aveas"]
    # per-recording reports written by the workers, equal to the API's
    v2 = next(e for e in rep.entries if e.path.endswith("v2.aveas"))
    full = json.loads(Path(v2.report_file).read_text())
    assert full["results"][0]["code"] == "structure.row_count"
    assert len(list((tmp_path / "reports").glob("*.json"))) == 5
    html = rep.to_html()
    assert "structure.row_count" in html and "corrupt.aveas.zip" in html and "<table>" in html
    # without the broken members: exit 1 (findings), and 0 with fail_on="never"
    good = [p for p in paths if "corrupt" not in p]
    assert ds.validate_dataset(good, workers=1).exit_code() == 1
    lenient = ds.validate_dataset(good, workers=1, fail_on="never")
    assert lenient.exit_code() == lenient.exit_code == 0 and lenient.exit_code("error") == 1


def test_a_recording_that_kills_its_worker_is_reported_and_the_rest_complete(dataset_root,
                                                                              tmp_path):
    paths = ds.discover(dataset_root)
    poison = tmp_path / "poison.aveas"
    poison.mkdir()
    rep = ds.validate_dataset([*paths, str(poison)], workers=2, task=validate_or_crash)
    assert [f.path for f in rep.failed] == [str(poison)]
    assert "worker process died" in rep.failed[0].error
    assert sorted(e.path for e in rep.entries) == sorted(paths)
    assert rep.exit_code() == 3


def test_catalog_rows_and_a_query(dataset_root, tmp_path):
    paths = ds.discover(dataset_root)
    table = ds.catalog(paths, workers=2)
    assert table.schema == ds.catalog_schema()
    assert table.num_rows == 5 and table.column("read_error").null_count == 5
    rows = {Path(r["path"]).name: r for r in table.to_pylist()}
    a1 = rows["a1.aveas"]
    rec = aveas_format.open(paths[0])
    s = rec.summary()
    assert a1["recording_id"] == "a1" and a1["partner"] == "KIT" and a1["method"] == "aerial"
    assert a1["road_type"] == "motorway" and a1["site"].startswith("A5")
    assert a1["duration_s"] == s["duration_s"] and a1["nominal_rate_hz"] == 10.0
    assert dict(a1["participants_per_class"]) == s["participants_per_class"]
    assert sum(a1[f"n_{c}"] for c in s["participants_per_class"]) == a1["n_participants"] == 6
    assert a1["n_states"] == rec.states.num_rows
    x0, y0, x1, y1 = shapely.from_wkt(rec.meta.coverage).bounds  # a rectangle
    assert a1["coverage_area_m2"] == pytest.approx((x1 - x0) * (y1 - y0)) and x1 - x0 > 400
    assert a1["start_time"].isoformat() == "2024-05-13T08:15:00+00:00"
    assert a1["valid"] and a1["errors"] == 0 and a1["validated"]
    ttc = rec.derived["interactions"].column("ttc").to_numpy(zero_copy_only=False)
    assert a1["min_ttc_s"] == pytest.approx(np.nanmin(ttc[np.isfinite(ttc)]))
    assert rows["u1.aveas"]["min_ttc_s"] is None and rows["u1.aveas"]["derived"] == []
    assert "derived/interactions" in a1["derived"]

    # the documented query: aerial motorway recordings with a TTC below a threshold (here just
    # above the smallest such TTC: the small sample highways have no conflict, docs/derive.md)
    out = ds.write_catalog(table, tmp_path / "catalog.parquet")
    threshold = 0.01 + min(r["min_ttc_s"] for r in rows.values() if r["method"] == "aerial"
                           and r["road_type"] == "motorway" and r["min_ttc_s"] is not None)
    dset = pads.dataset(out)
    hits = dset.to_table(
        columns=["recording_id", "partner", "min_ttc_s"],
        filter=(pc.field("method") == "aerial") & (pc.field("road_type") == "motorway")
        & (pc.field("min_ttc_s") < threshold))
    expected = sorted(r["recording_id"] for r in rows.values() if r["method"] == "aerial"
                      and r["road_type"] == "motorway" and r["min_ttc_s"] is not None
                      and r["min_ttc_s"] < threshold)
    assert sorted(hits.column("recording_id").to_pylist()) == expected and expected
    # CSV and JSON lines forms
    ds.write_catalog(table, tmp_path / "catalog.csv")
    ds.write_catalog(table, tmp_path / "catalog.jsonl")
    assert len((tmp_path / "catalog.jsonl").read_text().splitlines()) == 5
    assert ds.catalog(paths[:1], validate=False).column("valid").to_pylist() == [None]


def test_catalog_of_an_unreadable_recording_has_its_error(broken_dataset):
    table = ds.catalog(ds.discover(broken_dataset), validate=False)
    bad = [r for r in table.to_pylist() if r["read_error"]]
    assert [Path(r["path"]).name for r in bad] == ["corrupt.aveas.zip"]


def test_per_vehicle_stats_streams_partial_reads(dataset_root, monkeypatch):
    paths = ds.discover(dataset_root)
    reads = []
    real_open = open_recording

    def spy(path, **kw):
        reads.append(kw)
        return real_open(path, **kw)

    monkeypatch.setattr(reader, "open_recording", spy)
    t = ds.per_vehicle_stats(paths, "mean_speed",
                             filters={"partner": "KIT", "road_type": "motorway"}, workers=1)
    monkeypatch.undo()
    # only states x participant columns the metric needs, and only for matching recordings
    state_reads = [kw for kw in reads if kw.get("tables") == ["states"]]
    assert len(state_reads) == 2 and all(kw["columns"] == ["vx", "vy"] for kw in state_reads)
    assert set(t.column("recording_id").to_pylist()) == {"a1", "a2"}
    assert t.num_rows == 12
    # equal to the values computed from the whole recordings
    for rid, path in (("a1", paths[0]), ("a2", paths[1])):
        s = aveas_format.open(path).states
        pid = s.column("participant_id").to_numpy()
        speed = np.hypot(s.column("vx").to_numpy(), s.column("vy").to_numpy())
        sub = t.filter(pc.equal(t.column("recording_id"), rid))
        for p, v in zip(sub.column("participant_id").to_pylist(), sub.column("value").to_pylist()):
            assert v == pytest.approx(speed[pid == p].mean())
    # parallel gives the same; class filter; list filter; unknown metric
    t2 = ds.per_vehicle_stats(paths, "mean_speed", filters={"partner": "KIT",
                                                             "road_type": "motorway"}, workers=2)
    assert sorted(t2.column("value").to_pylist()) == sorted(t.column("value").to_pylist())
    trucks = ds.per_vehicle_stats(paths, "max_speed", classes=["truck"],
                                  filters={"method": ["aerial", "road_vehicle"]})
    assert set(trucks.column("class").to_pylist()) <= {"truck"}
    with pytest.raises(AveasError, match="unknown metric"):
        ds.per_vehicle_stats(paths, "nonsense")
    errors: list = []
    ds.per_vehicle_stats([*paths, "/nonexistent.aveas"], "samples", errors=errors)
    assert len(errors) == 1 and "no such recording" in errors[0]["error"]


def test_derive_dataset_writes_the_same_layout(dataset_root, tmp_path):
    paths = ds.discover(dataset_root / "kit")
    rep = ds.derive_dataset(paths, output_dir=tmp_path / "out", workers=2)
    assert not rep.failed and rep.exit_code() == 0
    outs = sorted(Path(e.output).relative_to(tmp_path / "out").as_posix() for e in rep.entries)
    assert outs == ["a1.aveas", "a2.aveas.zip", "u1.aveas"]
    u1 = aveas_format.open(tmp_path / "out" / "u1.aveas")
    assert "interactions" in u1.derived
    e = next(e for e in rep.entries if e.path.endswith("u1.aveas"))
    assert e.min_ttc_s == pytest.approx(ds.catalog([tmp_path / "out" / "u1.aveas"],
                                                      validate=False)["min_ttc_s"][0].as_py())
    with pytest.raises(AveasError):
        ds.derive_dataset(paths)
    assert "interactions" not in aveas_format.open(dataset_root / "kit" / "u1.aveas").derived


def test_remote_urls_are_listed_and_staged_per_task(dataset_root, monkeypatch):
    """An s3:// dataset, simulated by a pyarrow SubTreeFileSystem over a local directory: listing
    through pyarrow.fs, and each task working on a temporary local copy (in this process)."""
    import pyarrow.fs as pafs

    bucket_root = dataset_root.parent  # s3://bucket/archive/... -> dataset_root/...

    def from_uri(uri):
        assert uri.startswith("s3://bucket/")
        sub = pafs.SubTreeFileSystem(str(bucket_root), pafs.LocalFileSystem())
        return sub, uri[len("s3://bucket/"):]

    monkeypatch.setattr(discovery, "_filesystem_from_uri", from_uri)
    urls = ds.discover("s3://bucket/archive")
    assert urls == [f"s3://bucket/archive/{r}" for r in (
        "kit/a1.aveas", "kit/a2.aveas.zip", "kit/u1.aveas", "tub/v1.aveas", "tub/v2.aveas")]
    rep = ds.validate_dataset(urls, workers=1)
    assert not rep.failed and rep.exit_code() == 0 and len(rep.entries) == 5
    cat = ds.catalog(urls[:2], validate=False)
    assert cat.column("path").to_pylist() == urls[:2]
    assert cat.column("recording_id").to_pylist() == ["a1", "a2"]
    t = ds.per_vehicle_stats(urls, "samples", filters={"road_type": "urban"})
    assert set(t.column("recording_id").to_pylist()) == {"u1"}
