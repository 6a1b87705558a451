"""The OpenLABEL export of a recording on disk whose states are not loaded (``states=False``, the
CLI's ``export``): the states spilled in frame order and read one bucket at a time give the same
bytes as the export of the loaded recording — whatever the row groups (tracks cut between them),
buckets, chunks and worker processes, with the acceleration from the states, from the derived
kinematics or estimated along the tracks; a changed states file is refused before anything is
written, and no spill is left behind."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

import aveas_format
from aveas_format.io import timemajor
from aveas_format.converters.openlabel.write import openlabel_chunks
from aveas_format.errors import ChecksumError
from aveas_format.safeio import parts, write_chunks_atomic
from aveas_format.sample import highway_scene

from helpers_converters import rich_recording


@pytest.fixture
def small_spill(monkeypatch):
    """Spill every recording, in buckets of a few hundred rows; forked parts from any size."""
    monkeypatch.setattr(timemajor, "SPILL_MIN_ROWS", 0)
    monkeypatch.setattr(timemajor, "BUCKET_BYTES", 20_000)
    monkeypatch.setattr(parts, "PARTS_MIN_ROWS", 0)
    made = []
    real = timemajor.SpilledStates._spill
    monkeypatch.setattr(timemajor.SpilledStates, "_spill",
                        lambda self, *a: (real(self, *a), made.append(self.n_buckets))[0])
    return made


def _written(tmp_path: Path, rec, monkeypatch) -> Path:
    """``rec`` written with row groups of 97 rows (tracks cut between them)."""
    from aveas_format.io import writer

    monkeypatch.setattr(writer, "ROW_GROUP_ROWS", 97)
    return rec.write(tmp_path / "rec.aveas")


def _export(rec, out: Path, **kw) -> bytes:
    out.mkdir(exist_ok=True)
    data = write_chunks_atomic(out / "x.json", openlabel_chunks(rec, chunk_rows=40, spill_dir=out, **kw))
    assert [p.name for p in out.iterdir()] == ["x.json"]  # no spill and no part left
    return data.read_bytes()


def _kinematics(rec) -> pa.Table:
    """A derived kinematics table of ``rec`` (a row per state; the acceleration the export takes)."""
    n = rec.states.num_rows
    rng = np.random.default_rng(5)
    return pa.table({"participant_id": rec.states.column("participant_id"), "time": rec.states.column("time"),
                     "ax": rng.normal(size=n), "ay": rng.normal(size=n)})


@pytest.mark.parametrize("kind,workers,plain", [(k, w, True) for k in ("estimated", "states", "kinematics")
                                                for w in (1, 2)] + [("states", 2, False)])
def test_spilled_export_gives_the_loaded_exports_bytes(tmp_path, monkeypatch, small_spill, kind, workers, plain):
    """``plain``: the buckets' files uncompressed (few states), else lz4."""
    from aveas_format.io import resort as spill

    if not plain:
        monkeypatch.setattr(spill, "PLAIN_BUCKETS_BYTES", 0)
    rec = {"estimated": lambda: highway_scene(n_vehicles=10, duration_s=12.0, seed=4),
           "states": lambda: rich_recording(n_vehicles=6, duration_s=8.0),
           "kinematics": lambda: highway_scene(n_vehicles=10, duration_s=12.0, seed=4),
           }[kind]()
    assert ("ax" in rec.states.column_names) == (kind == "states")
    path = _written(tmp_path, rec, monkeypatch)
    loaded = aveas_format.open(path)
    lazy = aveas_format.open(path, states=False)
    assert lazy.states is None
    if kind == "kinematics":  # (in memory only: the same table for both)
        loaded.derived["kinematics"] = lazy.derived["kinematics"] = _kinematics(rec)
    want = _export(loaded, tmp_path / "loaded", workers=workers)
    assert not small_spill
    got = _export(lazy, tmp_path / "spilled", workers=workers)
    assert small_spill and small_spill[0] > 3  # (several buckets)
    assert got == want
    assert spill.bucket_options(1) is (spill.PLAIN if plain else spill.LZ4)


def test_a_few_states_are_read_whole(tmp_path, monkeypatch):
    rec = highway_scene(n_vehicles=4, duration_s=4.0, seed=1)
    path = _written(tmp_path, rec, monkeypatch)
    assert isinstance(timemajor.open_states(aveas_format.open(path, states=False), 300), timemajor.LoadedStates)
    monkeypatch.setattr(timemajor, "SPILL_MIN_ROWS", 0)
    spilled = timemajor.open_states(aveas_format.open(path, states=False), 300, tmp_path)
    try:
        assert isinstance(spilled, timemajor.SpilledStates)
        assert spilled.frame_of_row.dtype == np.int32
        np.testing.assert_array_equal(spilled.frame_of_row,
                                      np.unique(rec.states.column("time").to_numpy(), return_inverse=True)[1])
    finally:
        spilled.close()
    assert not spilled.dir.exists()


def test_a_changed_states_file_is_refused_before_anything_is_written(tmp_path, monkeypatch, small_spill):
    import json

    rec = highway_scene(n_vehicles=6, duration_s=6.0, seed=2)
    path = _written(tmp_path, rec, monkeypatch)
    meta = json.loads((path / "recording.json").read_text())
    meta["tables"]["states"]["sha256"] = "0" * 64
    (path / "recording.json").write_text(json.dumps(meta))
    lazy = aveas_format.open(path, states=False)  # (the states are not read: not hashed yet)
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(ChecksumError, match="SHA-256") as e:
        write_chunks_atomic(out / "x.json", openlabel_chunks(lazy, spill_dir=out))
    assert "states.parquet" in str(e.value)
    assert list(out.iterdir()) == []  # no output, no temporary file, no spill


def test_the_cli_export_reads_the_states_from_the_file(tmp_path, monkeypatch, small_spill):
    from aveas_format.cli import app
    from aveas_format.cli.common import run

    rec = highway_scene(n_vehicles=6, duration_s=6.0, seed=2)
    path = _written(tmp_path, rec, monkeypatch)
    assert run(app, ["export", "--to", "openlabel", str(path), "-o", str(tmp_path / "cli.json")]) == 0
    assert small_spill  # (spilled: the CLI opened the recording without its states)
    want = _export(aveas_format.open(path), tmp_path / "loaded")
    assert (tmp_path / "cli.json").read_bytes() == want.replace(b'"opendrive":"map.xodr"',
                                                                b'"opendrive":"cli.xodr"')


def test_a_compressed_export_spills_next_to_its_output(tmp_path, monkeypatch, small_spill):
    import gzip

    from aveas_format.converters import get_converter

    rec = highway_scene(n_vehicles=6, duration_s=6.0, seed=2)
    path = _written(tmp_path, rec, monkeypatch)
    dirs = []
    real = timemajor.SpilledStates.__init__
    monkeypatch.setattr(timemajor.SpilledStates, "__init__",
                        lambda self, r, rows, spill_dir=None, *a, **kw: (dirs.append(spill_dir), real(self, r, rows, spill_dir, *a, **kw))[1])
    export = get_converter("openlabel", "export")
    for name, r in (("loaded", aveas_format.open(path)), ("spilled", aveas_format.open(path, states=False))):
        (tmp_path / name).mkdir()
        export(r, tmp_path / name / "x.json.gz", options={"write_map": False})
    assert dirs == [tmp_path / "spilled"] and [p.name for p in (tmp_path / "spilled").iterdir()] == ["x.json.gz"]
    assert gzip.open(tmp_path / "spilled" / "x.json.gz").read() == gzip.open(tmp_path / "loaded" / "x.json.gz").read()
