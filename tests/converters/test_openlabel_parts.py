"""The OpenLABEL import that writes its recording itself (``convert_to``, the CLI's ``convert``):
the boxes held in bounded memory (spilled by :class:`~aveas_format.io.resort.StatesWriter`) and
written as the states a bucket of participants at a time give the in-memory import's recording —
our own export (the extension's exact values, float and object members) and foreign files (KITTI
as VCD writes it, objects that are no road users, sentinel sizes, states repeated at one time, a
frame key given twice, the boxes' own timestamps) with the same findings, whatever the buckets.
Nothing is left next to the output, on success or failure."""

from __future__ import annotations

import json
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, get_converter
from aveas_format.converters.openlabel import read
from aveas_format.converters.registry import convert_to
from aveas_format.errors import FormatError, RecordingExistsError
from aveas_format.io import resort
from aveas_format.sample import highway_scene

from helpers_common import DATA, REALDATA, STRAIGHT_MAP, shared
from helpers_converters import kitti_box, kitti_doc

KITTI_EXCERPT = DATA / "third_party" / "vcd__openlabel100_kitti_tracking_0016_excerpt.json"


@pytest.fixture
def small_buckets(monkeypatch):
    """Buckets of a few dozen boxes; every box spilled."""
    monkeypatch.setattr(resort, "BUCKET_BYTES", 5_000)
    monkeypatch.setattr(read, "IMPORT_MEMORY", 1)


def _both(src: Path, tmp_path: Path, name: str = "out.aveas", map_source=STRAIGHT_MAP, **options):
    """``(the in-memory import, the recording written in parts, its warnings, the in-memory
    import's warnings, what convert_to returned)``."""
    with warnings.catch_warnings(record=True) as w_mem:
        warnings.simplefilter("always")
        mem = convert("openlabel", [src], map_source=map_source, options=options)
    with warnings.catch_warnings(record=True) as w_parts:
        warnings.simplefilter("always")
        got = convert_to("openlabel", [src], tmp_path / name, map_source=map_source, options=options)
    return mem, aveas_format.open(tmp_path / name), [str(w.message) for w in w_parts], \
        [str(w.message) for w in w_mem], got


def _same(mem, disk, location_exact: bool = True) -> None:
    assert sorted(disk.tables()) == sorted(mem.tables())
    for name, table in mem.tables().items():
        assert disk.table(name).equals(table), name
    a, b = disk.meta.model_dump(), mem.meta.model_dump()
    for m in (a, b):
        m.pop("tables"), m.pop("recording_id")
    if not location_exact:  # (the mean summed per bucket: the last bits may differ)
        la, lb = a.pop("location"), b.pop("location")
        for k in ("lon", "lat"):
            assert la[k] == pytest.approx(lb[k], rel=1e-13, abs=1e-12)
        assert {k: v for k, v in la.items() if k not in ("lon", "lat")} == \
            {k: v for k, v in lb.items() if k not in ("lon", "lat")}
    assert a == b


def _nothing_left(tmp_path: Path) -> None:
    assert not [p for p in tmp_path.rglob(".*") if p.name.startswith((".openlabel", ".aveas"))]


def test_own_export_same_recording(tmp_path, small_buckets):
    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    mem, disk, said, said_mem, (returned, n, on_road) = _both(src, tmp_path, map_source=None)
    assert returned.states is None  # (written in parts, not loaded)
    assert n == disk.states.num_rows == rec.states.num_rows and on_road == n
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    _nothing_left(tmp_path)


def test_buckets_transformed_in_worker_processes(tmp_path, small_buckets, monkeypatch):
    """With workers, the buckets' boxes become states in forked processes: the same recording."""
    from aveas_format.converters.openlabel import boxes

    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    marks = tmp_path / "marks"
    marks.mkdir()
    real = boxes.states_of

    def marked(*a, **kw):
        (marks / str(os.getpid())).touch()
        return real(*a, **kw)

    monkeypatch.setattr(boxes, "states_of", marked)
    monkeypatch.setattr(read, "states_of", marked)
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path, map_source=None, workers=2)
    assert returned.states is None and n == rec.states.num_rows
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    assert len({p.name for p in marks.iterdir()} - {str(os.getpid())}) >= 1


def test_zip_form_same_recording(tmp_path, small_buckets):
    rec = highway_scene(n_vehicles=10, duration_s=6.0, seed=2)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    mem, disk, _, _, (returned, _, _) = _both(src, tmp_path, "out.aveas.zip", map_source=None)
    assert returned.states is None
    _same(mem, disk, location_exact=False)  # (opened with its tables' SHA-256 checked)


def _defects(tmp_path: Path) -> Path:
    """KITTI-like boxes (no static cuboid: the columnar path) with every defect the import drops
    per box or per state: a DontCare with sentinel sizes, a car with sentinel sizes only (left
    without boxes), a car whose boxes are cut short in one frame, two frames at one timestamp
    (repeated states), and a frame key given twice (the last one counts); the frames shuffled."""
    doc = kitti_doc(n=40, stamps=[1_600_000_000.0 + 0.1 * k for k in range(40)])
    del doc["objects"]["-2"]
    doc["objects"]["7"] = {"name": "Car7", "type": "Car"}
    doc["objects"]["8"] = {"name": "Tram8", "type": "Tram"}
    for k in range(40):
        fr = doc["frames"][str(k)]
        fr["objects"]["7"] = {"object_data": {"cuboid": [
            {"name": "box3D", "coordinate_system": "CAM_LEFT", "val": [1, 1, 30, 0, 0, 0, -1, -1, -1]}]}}
        fr["objects"]["8"] = {"object_data": {"cuboid": [kitti_box(30.0 + k, 3.5, 0.0, -1.5, 9.0, 3.0, 2.5)]}}
    doc["frames"]["2"]["objects"]["1"]["object_data"]["cuboid"][0]["val"][6:9] = [0.0, 1.5, 1.7]
    doc["frames"]["6"]["frame_properties"]["timestamp"] = doc["frames"]["5"]["frame_properties"]["timestamp"]
    keys = list(doc["frames"])  # (the frames in the file in another order than their keys')
    np.random.default_rng(3).shuffle(keys)
    doc["frames"] = {k: doc["frames"][k] for k in keys}
    text = json.dumps({"openlabel": doc})
    again = json.dumps({"objects": {"1": doc["frames"]["9"]["objects"]["1"]},
                        "frame_properties": doc["frames"]["9"]["frame_properties"]})
    text = text.replace('"frames": {', '"frames": {"9": ' + again + ", ", 1)  # (then "9" again)
    p = tmp_path / "defects.json"
    p.write_text(text)
    return p


def test_foreign_defects_same_recording_and_findings(tmp_path, small_buckets):
    src = _defects(tmp_path)
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path)
    assert returned.states is None
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    assert any("dropped 41 boxes with a sentinel or impossible size" in m for m in said), said
    assert any("repeat a (participant, time)" in m for m in said), said
    assert any("skipped 1 objects: 1 DontCare" in m for m in said), said


@pytest.mark.parametrize("src", [KITTI_EXCERPT], ids=["kitti_0016_excerpt"])
def test_kitti_as_vcd_writes_it(src, tmp_path, small_buckets):
    mem, disk, said, said_mem, (returned, _, _) = _both(src, tmp_path)
    assert returned.states is None
    _same(mem, disk, location_exact=False)
    assert said == said_mem


@REALDATA
def test_kitti_tracking_real(tmp_path, small_buckets):
    src = shared("data", "real", "vcd", "openlabel100_kitti_tracking_0003.json")
    mem, disk, said, said_mem, (returned, _, _) = _both(src, tmp_path)
    assert returned.states is None
    _same(mem, disk, location_exact=False)
    assert said == said_mem


def test_box_timestamps_resolved_over_all_boxes(tmp_path, small_buckets):
    """A foreign file whose boxes carry their own timestamps (their unit and epoch resolved over
    all boxes at once): written in parts, the same recording."""
    doc = kitti_doc(n=12)
    del doc["objects"]["-2"], doc["objects"]["-1"]
    for k in range(12):
        objs = doc["frames"][str(k)]["objects"]
        del objs["-1"]
        for u in ("0", "1"):
            objs[u]["object_data"]["cuboid"][0]["attributes"] = {
                "num": [{"name": "timestamp", "val": 1_600_000_000.0 + 0.1 * k + 0.01 * int(u)}]}
    src = tmp_path / "stamped.json"
    src.write_text(json.dumps({"openlabel": doc}))
    mem, disk, said, said_mem, (returned, _, _) = _both(src, tmp_path)
    assert returned.states is None
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    assert mem.states.column("time").to_pylist()[:2] == pytest.approx([0.0, 0.1])


def test_cli_convert_writes_in_parts(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from aveas_format.cli.app import app

    rec = highway_scene(n_vehicles=12, duration_s=6.0, seed=4)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    monkeypatch.setattr(read, "IMPORT_MEMORY", 1)
    monkeypatch.setattr(resort, "BUCKET_BYTES", 20_000)
    wrote = []
    real = resort._ParquetStates.add
    monkeypatch.setattr(resort._ParquetStates, "add", lambda self, s: (wrote.append(s.num_rows), real(self, s))[1])
    out = tmp_path / "cli.aveas"
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert len(wrote) > 1 and sum(wrote) == rec.states.num_rows  # (in parts: more than one bucket)
    assert f"{rec.states.num_rows:,} states, 100.0% on the map" in r.output
    _same(convert("openlabel", [src]), aveas_format.open(out), location_exact=False)
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(src), "-o", str(out)])
    assert r.exit_code == 2 and "exists" in r.output


def test_existing_output_refused_before_reading(tmp_path):
    (tmp_path / "out.aveas").mkdir()
    with pytest.raises(RecordingExistsError):
        convert_to("openlabel", [KITTI_EXCERPT], tmp_path / "out.aveas", map_source=STRAIGHT_MAP)


@pytest.mark.parametrize("workers", [1, 2])
def test_broken_file_leaves_nothing(tmp_path, small_buckets, monkeypatch, workers):
    """A file cut short: refused, nothing next to the output (with workers: they are done before
    the spill is removed)."""
    from aveas_format.converters.openlabel import source

    monkeypatch.setattr(source, "BLOCK", 1 << 14)  # (many blocks)
    monkeypatch.setattr(read, "SMALL", 0)
    rec = highway_scene(n_vehicles=8, duration_s=5.0, seed=1)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    text = src.read_bytes()
    cut = tmp_path / "cut.json"
    cut.write_bytes(text[: len(text) * 2 // 3])
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(FormatError):
        convert_to("openlabel", [cut], out / "rec.aveas", options={"workers": workers})
    assert list(out.iterdir()) == []


def _report(src: Path, monkeypatch, memory: int) -> dict:
    from typer.testing import CliRunner

    from aveas_format.cli.app import app

    monkeypatch.setattr(read, "IMPORT_MEMORY", memory)
    r = CliRunner().invoke(app, ["validate", str(src), "--map", str(STRAIGHT_MAP), "--format", "json"])
    assert r.exit_code in (0, 1), r.output
    report = json.loads(r.stdout)

    def strip(d):
        if isinstance(d, dict):
            return {k: strip(v) for k, v in d.items() if k not in ("seconds", "streamed")}
        return [strip(x) for x in d] if isinstance(d, list) else d
    return strip(report)


def test_validate_submission_through_the_written_recording(tmp_path, small_buckets, monkeypatch):
    """``validate FILE`` of a large file validates the recording written in parts (a temporary
    directory, removed after): the same report, the import's findings located in the file."""
    src = _defects(tmp_path)
    written = []
    real = resort.StatesWriter.write
    monkeypatch.setattr(resort.StatesWriter, "write",
                        lambda self, target, **kw: (written.append(Path(target)), real(self, target, **kw))[1])
    on_disk = _report(src, monkeypatch, 1)
    assert written and not written[0].exists()  # (in parts, in a temporary directory since removed)
    in_memory = _report(src, monkeypatch, 10**12)
    assert on_disk == in_memory
    codes = {r["code"] for r in on_disk["results"] if r.get("count")}
    assert {"source.openlabel.bad_size", "source.openlabel.duplicate_state"} <= codes, codes


def test_buckets_with_other_columns_written_in_one_schema(tmp_path, small_buckets):
    """A column only a later bucket has (a light only the last participant shows): the states are
    written in one schema, null where a bucket lacks it — the same recording as in memory."""
    rec = highway_scene(n_vehicles=12, duration_s=6.0, seed=4)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src, options={"extension": False})
    doc = json.loads(src.read_text())
    last = max(doc["openlabel"]["objects"], key=int)
    shown = 0
    for fr in doc["openlabel"]["frames"].values():
        box = fr["objects"].get(last)
        if box is not None:
            box["object_data"].setdefault("num", []).append({"name": "lights/brake", "val": 0.75})
            shown += 1
    assert shown
    src.write_text(json.dumps(doc))
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path, map_source=None)
    assert returned.states is None
    assert disk.states.column("light_brake_p").null_count == n - shown
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    _nothing_left(tmp_path)


@pytest.mark.parametrize("seed", range(5))
def test_objects_first_seen_in_frame_key_order(seed):
    """The objects in order of their first appearance over the frames kept, in key order (what
    numbers the objects a file's ``objects`` lacks): the same as a sort of all boxes, for frames
    in blocks of any size, empty frames and frame keys given twice (rank -1)."""
    from aveas_format.converters.openlabel.boxes import Boxes

    rng = np.random.default_rng(seed)
    acc = Boxes(None)
    n_frames, n_objects = 300, 40
    lens = rng.integers(0, 6, n_frames)
    frames = [rng.choice(n_objects, int(k), replace=False).astype(np.int32) for k in lens]
    acc.uid_index = {str(i): i for i in range(n_objects)}
    cuts = np.sort(rng.choice(np.arange(1, n_frames), 20, replace=False))
    acc.slots = [np.concatenate(frames[a:b]) if b > a else np.zeros(0, np.int32)
                 for a, b in zip([0, *cuts], [*cuts, n_frames])]
    acc.frame_len = [lens[a:b].astype(np.int32) for a, b in zip([0, *cuts], [*cuts, n_frames])]
    rank_of = rng.permutation(n_frames).astype(np.int64)
    rank_of[rng.choice(n_frames, 30, replace=False)] = -1  # (occurrences of a key given again)
    flat = np.concatenate([frames[j] for j in np.argsort(np.where(rank_of < 0, n_frames + 1, rank_of))
                           if rank_of[j] >= 0])
    uniq, first = np.unique(flat, return_index=True)
    assert acc._first_seen(rank_of) == uniq[np.argsort(first)].tolist()
    acc.close()
