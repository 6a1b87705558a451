"""The OpenLABEL import that writes its recording itself (``convert_to``, the CLI's ``convert``):
the boxes spilled as they are read, bucketed by participant and written as the states in parts
give the in-memory import's recording — our own export (the extension's exact values, float and
object members) and foreign files (KITTI as VCD writes it, objects that are no road users,
sentinel sizes, states repeated at one time, a frame key given twice) with the same findings,
whatever the buckets; where a step needs the rows in memory (the boxes' own timestamps, a block
Arrow cannot hold exactly) they are read back and the result is the same. Nothing is left next
to the output, on success or failure."""

from __future__ import annotations

import json
import os
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import aveas_format
from aveas_format.converters import convert, get_converter
from aveas_format.converters.openlabel import parts, spill
from aveas_format.converters.registry import convert_to
from aveas_format.errors import FormatError, RecordingExistsError
from aveas_format.sample import highway_scene

from helpers_common import DATA, REALDATA, STRAIGHT_MAP, shared
from helpers_converters import kitti_box, kitti_doc

KITTI_EXCERPT = DATA / "third_party" / "vcd__openlabel100_kitti_tracking_0016_excerpt.json"


@pytest.fixture
def small_buckets(monkeypatch):
    """Buckets of a few dozen boxes."""
    monkeypatch.setattr(parts, "BUCKET_BYTES", 5_000)


def _both(src: Path, tmp_path: Path, name: str = "out.aveas", map_source=STRAIGHT_MAP, **options):
    """``(the in-memory import, the recording written in parts, its warnings, the in-memory
    import's warnings, the parts' return)``."""
    with warnings.catch_warnings(record=True) as w_mem:
        warnings.simplefilter("always")
        mem = convert("openlabel", [src], map_source=map_source, options=options)
    with warnings.catch_warnings(record=True) as w_parts:
        warnings.simplefilter("always")
        got = parts.import_openlabel_to([src], tmp_path / name, map_source=map_source,
                                        options=get_converter("openlabel").parse_options(options),
                                        min_rows=0)
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


def test_own_export_same_recording(tmp_path, small_buckets):
    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    mem, disk, said, said_mem, (returned, n, on_road) = _both(src, tmp_path, map_source=None)
    assert returned.states is None  # (written in parts, not loaded)
    assert n == disk.states.num_rows == rec.states.num_rows and on_road == n
    _same(mem, disk)
    assert said == said_mem
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_pass_in_two_halves_same_recording(tmp_path, small_buckets, monkeypatch):
    """The spill of many blocks is put into buckets by two worker processes, half of the spill
    each (their bucket files read in file order): the same recording."""
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 1 << 16)
    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    real = parts._Buckets._pass_part
    marks = tmp_path / "marks"
    marks.mkdir()

    def marked(self, part):  # (in the worker processes: a file each, with its process id)
        (marks / f"{part[0]}.{part[1]}.{part[2]}").write_text(str(os.getpid()))
        return real(self, part)

    monkeypatch.setattr(parts._Buckets, "_pass_part", marked)
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path, map_source=None, workers=2)
    assert returned.states is None and n == rec.states.num_rows
    _same(mem, disk)
    assert said == said_mem
    halves = sorted(tuple(map(int, f.name.split("."))) for f in marks.iterdir())
    assert [h[0] for h in halves] == [0, 1] and halves[0][2] == halves[1][1] > 0  # (adjacent halves)
    assert os.getpid() not in {int(f.read_text()) for f in marks.iterdir()}


def _marked(monkeypatch, marks: Path, module, name: str) -> None:
    """``module.name`` leaves a file named after the calling process (forked workers too)."""
    real = getattr(module, name)

    def marked(*args, **kw):
        (marks / f"{name}.{os.getpid()}.{time.monotonic_ns()}").touch()
        return real(*args, **kw)

    monkeypatch.setattr(module, name, marked)


def _pids(marks: Path, name: str) -> set[int]:
    return {int(f.name.split(".")[1]) for f in marks.iterdir() if f.name.startswith(name + ".")}


def test_blocks_spilled_by_the_workers_that_read_them(tmp_path, small_buckets, monkeypatch):
    """Once the spill has begun, each block's columns are written into it by the worker process
    that read the block (not sent back) and adopted by the spill: the same recording."""
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 1 << 16)
    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    marks = tmp_path / "marks"
    marks.mkdir()
    _marked(monkeypatch, marks, spill, "write_rows")
    adopted = []
    real = spill.RowSpill.adopt
    monkeypatch.setattr(spill.RowSpill, "adopt", lambda self, *a: (adopted.append(a[0][1]), real(self, *a))[1])
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path, map_source=None, workers=2)
    assert returned.states is None and n == rec.states.num_rows
    _same(mem, disk)
    assert said == said_mem
    workers = _pids(marks, "write_rows")
    assert workers and os.getpid() not in workers
    assert len(adopted) > 10 and sum(adopted) < n  # (the first blocks, sent before the spill began: here)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_blocks_spilled_by_workers_after_the_spill_ended_are_read_back(tmp_path, small_buckets, monkeypatch):
    """A block the spill cannot hold (here: the second one spilled here) ends it while later
    blocks, sent while it was on, are written into it by the workers: those are read back into
    memory as they come; the same recording, nothing left."""
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 1 << 16)
    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    here, calls = os.getpid(), {"n": 0}
    real_to_batch = spill.to_batch

    def second_here_fails(ch, ext):
        if os.getpid() == here:
            calls["n"] += 1
            if calls["n"] == 2:
                return None
        return real_to_batch(ch, ext)

    monkeypatch.setattr(spill, "to_batch", second_here_fails)
    back = []
    real_read = spill.read_rows
    from aveas_format.converters.openlabel import frames
    monkeypatch.setattr(frames, "read_rows", lambda path: (back.append(path), real_read(path))[1])
    mem, disk, said, said_mem, (returned, _, _) = _both(src, tmp_path, map_source=None, workers=2)
    assert returned.states is not None  # (in memory)
    _same(mem, disk)
    assert back and not any(os.path.exists(p) for p in back)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_file_read_frame_by_frame_spilled_once_its_rows_are_many(tmp_path, small_buckets, monkeypatch):
    """Boxes the block readers do not take (rolled a little: placed one at a time, the file read
    frame by frame, its rows not estimated before the frames) are held in memory until their
    rows reach the spill's threshold, then those rows and the rest are spilled: the same
    recording."""
    from aveas_format.converters.openlabel import frames

    rec = highway_scene(n_vehicles=30, duration_s=12.0, seed=5)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    doc = json.loads(src.read_text())
    for fr in doc["openlabel"]["frames"].values():
        for box in fr["objects"].values():
            box["object_data"]["cuboid"][0]["val"][3] = 0.001  # (a roll: not the blocks' layout)
    src.write_text(json.dumps(doc, separators=(",", ":")))
    monkeypatch.setattr(frames, "_CHUNK", 500)  # (the boxes converted 500 at a time)
    kept = []
    real = frames._FrameRows._keep

    def keep(self, ch, ext, found, js, us, uidx=None):
        kept.append((len(us), self.spill is not None))
        return real(self, ch, ext, found, js, us, uidx)

    monkeypatch.setattr(frames._FrameRows, "_keep", keep)
    threshold = rec.states.num_rows // 3
    mem = convert("openlabel", [src])
    got, n, _ = parts.import_openlabel_to([src], tmp_path / "out.aveas", options=get_converter(
        "openlabel").parse_options({}), min_rows=threshold)
    assert got.states is None and n == rec.states.num_rows  # (written in parts)
    assert len(kept) > 6 and not any(spilling for _, spilling in kept[:len(kept) // 2])  # (in memory)
    ours = kept[len(kept) // 2:]
    assert ours[0][1] is False and ours[-1][1] is True  # (held, then spilled)
    _same(mem, aveas_format.open(tmp_path / "out.aveas"))
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_zip_form_same_recording(tmp_path, small_buckets):
    rec = highway_scene(n_vehicles=10, duration_s=6.0, seed=2)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    mem, disk, _, _, (returned, _, _) = _both(src, tmp_path, "out.aveas.zip", map_source=None)
    assert returned.states is None
    _same(mem, disk)  # (opened with its tables' SHA-256 checked)


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


def test_box_timestamps_need_the_rows_in_memory(tmp_path, small_buckets):
    """A foreign file whose boxes carry their own timestamps (resolved over all boxes at once):
    the rows are read back into memory, the recording the same."""
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
    assert returned.states is not None  # (in memory after all)
    _same(mem, disk)
    assert said == said_mem


def test_a_block_arrow_cannot_hold_is_read_back(tmp_path, small_buckets, monkeypatch):
    """Values Arrow would not give back exactly (here: no text allowed) end the spill: the rows
    are read back into memory and the import goes on; the same recording, nothing left."""
    rec = highway_scene(n_vehicles=8, duration_s=5.0, seed=1)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    loaded = []
    real = spill.RowSpill.load_into
    monkeypatch.setattr(spill.RowSpill, "load_into", lambda self, keep: (loaded.append(self.n), real(self, keep)))
    calls = {"n": 0}
    real_to_batch = spill.to_batch

    def second_fails(ch, ext):  # the first block spills, the second cannot
        calls["n"] += 1
        return None if calls["n"] == 2 else real_to_batch(ch, ext)

    monkeypatch.setattr(spill, "to_batch", second_fails)
    from aveas_format.converters.openlabel import stream
    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 1 << 14)  # (many blocks)
    mem, disk, said, said_mem, (returned, _, _) = _both(src, tmp_path, map_source=None)
    assert returned.states is not None
    _same(mem, disk)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_spill_round_trip_is_exact():
    """A block's columns and extension members through Arrow and back: the same values (texts,
    integers, booleans and None in object columns; a member missing vs null)."""
    from aveas_format.converters.openlabel.columns import _MISSING

    obj = np.empty(4, object)
    obj[:] = ["a", None, "b", "c"]
    lanes = np.empty(4, object)
    lanes[:] = [-1, 2, None, -3]
    flags = np.empty(4, object)
    flags[:] = [True, _MISSING, None, False]
    ch = {"px": np.array([1.0, np.nan, 3.0, 4.0]), "hv": np.array([True, False, True, True]),
          "road_id": obj, "lane_id": lanes, "uidx": np.arange(4), "occ": np.arange(4)}
    ext = {"vx": ("f", np.array([1.0, 2.0, np.nan, 0.0]), np.array([True, True, False, True]),
                  np.array([False, False, False, True])), "interpolated": ("o", flags)}
    bools = np.empty(4, object)
    bools[:] = [True, False, True, True]  # (an object column of booleans stays one)
    ch["bools"] = bools
    ch["csroot"] = np.full(4, None, object)
    batch = spill.to_batch(ch, ext)
    import pyarrow as pa

    typed = lambda a: [(type(v), v) for v in a.tolist()]  # noqa: E731  (1 == 1.0 == True: the types too)
    for back, back_ext in (spill.from_table(batch), spill.from_table(pa.Table.from_batches([batch.slice(0, 1),
                                                                                          batch.slice(1)]))):
        for c in ("px", "hv", "bools"):
            np.testing.assert_array_equal(back[c], ch[c])
            assert back[c].dtype == ch[c].dtype, c
        for c in ("road_id", "lane_id", "bools", "csroot"):
            assert back[c].dtype == object and typed(back[c]) == typed(ch[c]), c
        assert typed(back_ext["interpolated"][1][[0, 2, 3]]) == typed(flags[[0, 2, 3]])
    for a, b in zip(back_ext["vx"], ext["vx"]):
        np.testing.assert_array_equal(a, b)
    assert [v is _MISSING for v in back_ext["interpolated"][1]] == [False, True, False, False]
    assert back_ext["interpolated"][1][[0, 2, 3]].tolist() == [True, None, False]
    mixed = np.empty(2, object)
    mixed[:] = [1, 2.5]  # (an integer among floats: Arrow would make it 1.0)
    assert spill.to_batch({"lane_id": mixed}, {}) is None
    mixed[:] = ["1", 2]  # (a number among texts)
    assert spill.to_batch({"road_id": mixed}, {}) is None


@pytest.mark.parametrize("options", ["LZ4", "PLAIN"])
def test_spill_files_written_through_a_buffer_read_back_whole(tmp_path, options):
    """The spills' writers (a buffer under Arrow's IPC writer, its thread pool unused): every
    small batch of many buckets read back in order; a file writer's file; closing twice is
    harmless; a writer that cannot start leaves its file closed."""
    import pyarrow as pa

    opts = getattr(spill, options)
    rng = np.random.default_rng(3)
    n = 5000
    table = pa.table({f"c{i}": rng.normal(size=n) for i in range(30)} | {"k": np.arange(n)})
    buckets = np.sort(rng.integers(0, 40, n))
    writers: dict = {}
    try:
        for lo in range(0, n, 700):  # (slices of a few rows per bucket, as the import's pass writes them)
            spill.write_by_bucket(writers, table.slice(lo, 700), buckets[lo:lo + 700],
                                  lambda k: tmp_path / f"b{k}.arrow", opts)
    finally:
        for w in writers.values():
            w.close()
    got = []
    for k in sorted(writers):
        with pa.OSFile(str(tmp_path / f"b{k}.arrow")) as f:
            t = pa.ipc.open_stream(f, options=spill.READ).read_all()
        assert len(t) == int((buckets == k).sum())
        got.append(t)
    assert pa.concat_tables(got).equals(table)
    with spill.IpcWriter(tmp_path / "f.arrow", table.schema, opts, file=True) as w:
        w.write_table(table)
        w.write_batch(table.to_batches()[0].slice(0, 3))
    w.close()
    with pa.OSFile(str(tmp_path / "f.arrow")) as f:
        r = pa.ipc.open_file(f, options=spill.READ)
        assert r.num_record_batches >= 2 and r.read_all().num_rows == n + 3
    with pytest.raises((TypeError, pa.ArrowException)):
        spill.IpcWriter(tmp_path / "g.arrow", "not a schema", opts)
    if os.path.isdir("/proc/self/fd"):  # (Linux: no descriptor left open on it)
        assert not any(os.path.realpath(f"/proc/self/fd/{fd}").endswith("g.arrow") for fd in os.listdir("/proc/self/fd"))


def test_cli_convert_writes_in_parts(tmp_path, monkeypatch):
    from typer.testing import CliRunner

    from aveas_format.cli.app import app

    rec = highway_scene(n_vehicles=12, duration_s=6.0, seed=4)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    monkeypatch.setattr(parts, "SPILL_MIN_ROWS", 0)
    monkeypatch.setattr(parts, "BUCKET_BYTES", 20_000)
    wrote = []
    real = parts._StatesWriter.add
    monkeypatch.setattr(parts._StatesWriter, "add", lambda self, s: (wrote.append(s.num_rows), real(self, s))[1])
    out = tmp_path / "cli.aveas"
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(src), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert len(wrote) > 1 and sum(wrote) == rec.states.num_rows  # (in parts: more than one bucket)
    assert f"{rec.states.num_rows:,} states, 100.0% on the map" in r.output
    _same(convert("openlabel", [src]), aveas_format.open(out))
    r = CliRunner().invoke(app, ["convert", "--from", "openlabel", str(src), "-o", str(out)])
    assert r.exit_code == 2 and "exists" in r.output


def test_existing_output_refused_before_reading(tmp_path):
    (tmp_path / "out.aveas").mkdir()
    with pytest.raises(RecordingExistsError):
        convert_to("openlabel", [KITTI_EXCERPT], tmp_path / "out.aveas", map_source=STRAIGHT_MAP)


@pytest.mark.parametrize("workers", [1, 2])
def test_broken_file_leaves_nothing(tmp_path, small_buckets, monkeypatch, workers):
    """A file cut short: refused, nothing next to the output (with workers: they are done before
    the spill is removed, none writes into it after)."""
    from aveas_format.converters.openlabel import stream

    monkeypatch.setattr(stream, "_COLUMNAR_BLOCK", 1 << 14)  # (many blocks)
    rec = highway_scene(n_vehicles=8, duration_s=5.0, seed=1)
    src = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, src)
    text = src.read_bytes()
    cut = tmp_path / "cut.json"
    cut.write_bytes(text[: len(text) * 2 // 3])
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(FormatError):
        parts.import_openlabel_to([cut], out / "rec.aveas",
                                  options=get_converter("openlabel").parse_options({"workers": workers}),
                                  min_rows=0)
    assert list(out.iterdir()) == []


def _report(src: Path, monkeypatch, min_rows: int) -> dict:
    from typer.testing import CliRunner

    from aveas_format.cli.app import app

    monkeypatch.setattr(parts, "SPILL_MIN_ROWS", min_rows)
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
    real = parts._Buckets._written
    monkeypatch.setattr(parts._Buckets, "_written", lambda self, *a: (written.append(self.dir), real(self, *a))[1])
    on_disk = _report(src, monkeypatch, 0)
    assert written and not written[0].exists()  # (in parts, in a temporary directory since removed)
    in_memory = _report(src, monkeypatch, 10**9)
    assert on_disk == in_memory
    codes = {r["code"] for r in on_disk["results"] if r.get("count")}
    assert {"source.openlabel.bad_size", "source.openlabel.duplicate_state"} <= codes, codes


def test_buckets_with_other_columns_written_in_one_schema(tmp_path, small_buckets, monkeypatch):
    """The buckets' states are written as they come while the workers go on; where a later
    bucket has a column the first has not (a light only the last participant shows), that
    write is given up and the buckets are written after all of them, in one schema: the same
    recording as in memory."""
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
    given_up, streamed = [], []
    abort, add = parts._StatesWriter.abort, parts._StatesWriter.add
    monkeypatch.setattr(parts._StatesWriter, "abort", lambda self: (given_up.append(1), abort(self))[1])
    monkeypatch.setattr(parts._StatesWriter, "add", lambda self, s: (streamed.append(s.num_rows), add(self, s))[1])
    mem, disk, said, said_mem, (returned, n, _) = _both(src, tmp_path, map_source=None)
    assert returned.states is None and given_up == [1]
    assert sum(streamed) > n  # (the buckets before the last streamed, then all written again)
    assert disk.states.column("light_brake_p").null_count == n - shown
    _same(mem, disk, location_exact=False)
    assert said == said_mem
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_one_schema_over_the_buckets():
    """The buckets' states make one schema: the format's columns in its order, others by name, a
    type that holds every bucket's values (a column all null in one bucket takes the others'
    type); types that do not go together: None (the import then runs in memory)."""
    import pyarrow as pa

    one = parts._one_schema([pa.schema([("zz", pa.null()), ("time", pa.float64())]),
                             pa.schema([("participant_id", pa.int64()), ("aa", pa.string()), ("zz", pa.bool_())])])
    assert one.names == ["participant_id", "time", "aa", "zz"]
    assert one.field("zz").type == pa.bool_()
    assert parts._one_schema([pa.schema([("x", pa.string())]), pa.schema([("x", pa.int64())])]) is None


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("group", [7, 1 << 20])
def test_objects_first_seen_in_frame_key_order(seed, group, monkeypatch):
    """The objects in order of their first appearance over the frames kept, in key order (what
    numbers the objects a file's ``objects`` lacks): the same as a sort of all boxes, for frames
    in parts of any size, empty frames and frame keys given twice (rank -1)."""
    from aveas_format.converters.openlabel import frames as fr
    from aveas_format.converters.openlabel.frames import _Frames, _FrameRows

    monkeypatch.setattr(fr, "_SEEN_GROUP", group)  # (7: many groups)
    rng = np.random.default_rng(seed)
    acc = _FrameRows({}, _Frames(None), None)
    n_frames, n_objects = 300, 40
    lens = rng.integers(0, 6, n_frames)
    frames = [rng.choice(n_objects, int(k), replace=False).astype(np.int32) for k in lens]
    acc.uid_index = {str(i): i for i in range(n_objects)}
    acc.frame_len = lens.tolist()
    cuts = np.sort(rng.choice(np.arange(1, n_frames), 20, replace=False))
    acc.uid_parts = [np.concatenate(frames[a:b]) if b > a else np.zeros(0, np.int32)
                     for a, b in zip([0, *cuts], [*cuts, n_frames])]
    rank_of = rng.permutation(n_frames).astype(np.int64)
    rank_of[rng.choice(n_frames, 30, replace=False)] = -1  # (occurrences of a key given again)
    flat = np.concatenate([frames[j] for j in np.argsort(np.where(rank_of < 0, n_frames + 1, rank_of))
                           if rank_of[j] >= 0])
    uniq, first = np.unique(flat, return_index=True)
    assert acc._first_seen(rank_of).tolist() == uniq[np.argsort(first)].tolist()
