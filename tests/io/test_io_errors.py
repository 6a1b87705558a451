"""Damaged recordings give clear errors that name the file and the problem."""

from __future__ import annotations

import json
import shutil

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.errors import (
    AveasError,
    ChecksumError,
    FormatError,
    FormatVersionError,
    RecordingIOError,
)


def test_missing_recording(tmp_path):
    with pytest.raises(RecordingIOError, match="no such recording") as e:
        aveas_format.open(tmp_path / "nope.aveas")
    assert isinstance(e.value, OSError) and isinstance(e.value, AveasError)
    assert "nope.aveas" in str(e.value)


def test_not_a_recording(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("hello")
    with pytest.raises(RecordingIOError, match="neither a directory nor a ZIP"):
        aveas_format.open(f)



@pytest.mark.parametrize("cut,name,match", [
    (0.5, "r.aveas.zip", "truncated or corrupt ZIP archive: no end-of-central-directory record"),
    (0.5, "r.bin", "truncated or corrupt ZIP archive: no end-of-central-directory record"),
    (0.0, "r.aveas.zip", "truncated or corrupt ZIP archive: the file is empty"),
    (None, "r.aveas.zip", "named .zip but not a ZIP archive"),
])
def test_a_truncated_zip_says_so(tmp_path, rec, cut, name, match):
    """A download cut short is a truncated ZIP, not "neither a directory nor a ZIP archive"."""
    data = rec.write(tmp_path / "whole.aveas.zip").read_bytes()
    (tmp_path / name).write_bytes(b"not a zip at all" if cut is None else data[:int(len(data) * cut)])
    with pytest.raises(RecordingIOError, match=match):
        aveas_format.open(tmp_path / name)

@pytest.mark.parametrize("name", ["states.parquet", "participants.parquet", "map.xodr",
                                  "recording.json"])
def test_missing_file(written, name):
    (written / name).unlink()
    with pytest.raises(RecordingIOError, match="missing") as e:
        aveas_format.open(written)
    assert name in str(e.value)


def test_truncated_parquet(written):
    p = written / "states.parquet"
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(ChecksumError, match="states.parquet.*SHA-256"):
        aveas_format.open(written)
    # without checksum verification the damage is still named
    with pytest.raises(RecordingIOError, match="states.parquet.*(truncated|corrupt)"):
        aveas_format.open(written, verify=False)


def _rewrite_states(written, fn, fix_checksum=True):
    p = written / "states.parquet"
    t = pq.read_table(p)
    t = fn(t)
    pq.write_table(t, p)
    if fix_checksum:
        meta = json.loads((written / "recording.json").read_text())
        import hashlib

        meta["tables"]["states"]["sha256"] = hashlib.sha256(p.read_bytes()).hexdigest()
        meta["tables"]["states"]["rows"] = t.num_rows
        (written / "recording.json").write_text(json.dumps(meta))


def test_wrong_column_type(written):
    def to_text(t):
        i = t.column_names.index("x")
        return t.set_column(i, "x", t.column("x").cast(pa.string()))

    _rewrite_states(written, to_text)
    with pytest.raises(FormatError, match=r"states.parquet.*column 'x' has type string.*float64"):
        aveas_format.open(written)


def test_missing_required_column(written):
    _rewrite_states(written, lambda t: t.drop_columns(["heading"]))
    with pytest.raises(FormatError, match=r"states.parquet.*required column 'heading' missing"):
        aveas_format.open(written)


def test_missing_aveas_key(written):
    _rewrite_states(written, lambda t: t.replace_schema_metadata({}))
    with pytest.raises(FormatError, match="states.parquet.*'aveas' missing"):
        aveas_format.open(written)


def test_broken_json(written):
    (written / "recording.json").write_text('{"format_version": "1.0.0",\n  "recording_id": }')
    with pytest.raises(FormatError, match=r"recording.json: line 2, column 19: broken JSON"):
        aveas_format.open(written)


def test_invalid_metadata_names_the_field(written):
    meta = json.loads((written / "recording.json").read_text())
    meta["acquisition"]["method"] = "satellite"
    (written / "recording.json").write_text(json.dumps(meta))
    with pytest.raises(FormatError, match=r"recording.json.*acquisition.method: Input should be"):
        aveas_format.open(written)


def test_checksum_mismatch(written):
    meta = json.loads((written / "recording.json").read_text())
    meta["tables"]["participants"]["sha256"] = "0" * 64
    (written / "recording.json").write_text(json.dumps(meta))
    with pytest.raises(ChecksumError, match="participants.parquet: SHA-256 differs"):
        aveas_format.open(written)


def test_row_count_mismatch(written):
    meta = json.loads((written / "recording.json").read_text())
    meta["tables"]["states"]["rows"] += 1
    (written / "recording.json").write_text(json.dumps(meta))
    with pytest.raises(ChecksumError, match=r"states.parquet: \d+ rows, recording.json says"):
        aveas_format.open(written)


def test_map_checksum(written):
    with open(written / "map.xodr", "a") as f:
        f.write("<!-- edited -->")
    with pytest.raises(ChecksumError, match="map.xodr"):
        aveas_format.open(written)


@pytest.mark.parametrize("version,match", [
    ("2.0.0", "newer than this library"),
    ("0.5.0", "no migration leads from it"),
    ("one", "semantic version"),
])
def test_unsupported_format_version(written, version, match):
    meta = json.loads((written / "recording.json").read_text())
    meta["format_version"] = version
    (written / "recording.json").write_text(json.dumps(meta))
    with pytest.raises(FormatVersionError, match=match) as e:
        aveas_format.open(written)
    assert isinstance(e.value, ValueError)


def test_zip_errors_name_the_member(tmp_path, rec):
    z = rec.write(tmp_path / "r.aveas.zip")
    data = bytearray(z.read_bytes())
    i = data.find(b"PAR1")  # corrupt the first Parquet member's magic bytes
    data[i:i + 4] = b"XXXX"
    z.write_bytes(bytes(data))
    with pytest.raises(AveasError, match=r"r.aveas.zip!(participants|states).parquet"):
        aveas_format.open(z)


def test_unlisted_extra_table_is_read(written, rec):
    shutil.copy(written / "states.parquet", written / "interior.parquet")
    with pytest.raises(FormatError, match="interior.parquet.*'aveas' names table 'states'"):
        aveas_format.open(written)


def test_a_write_into_a_missing_directory_says_so(tmp_path, rec):
    """Atomic writes name the target and its missing directory, not their temporary file."""
    from aveas_format.safeio import write_text_atomic

    target = tmp_path / "no" / "such" / "report.html"
    with pytest.raises(RecordingIOError) as e:
        write_text_atomic(target, "x")
    assert str(e.value) == f"{target}: cannot write: the directory {target.parent} does not exist"
    assert ".tmp" not in str(e.value)
    (tmp_path / "file").write_text("x")
    with pytest.raises(RecordingIOError, match="is not a directory"):
        write_text_atomic(tmp_path / "file" / "r.html", "x")
