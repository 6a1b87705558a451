"""Format versions: the frozen example of every released version is read forever; migrations."""

from __future__ import annotations

import hashlib
import json
import shutil

import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.schema import versions

from helpers_common import DATA

FROZEN = {"1.0.0": DATA / "versions" / "1.0.0" / "example.aveas"}


@pytest.mark.parametrize("version", sorted(FROZEN))
def test_frozen_example_is_read_and_valid(version):
    rec = aveas_format.open(FROZEN[version])
    assert rec.meta.format_version == versions.FORMAT_VERSION
    expected = None if version == versions.FORMAT_VERSION else version
    assert rec.migrated_from == expected
    assert rec.states.num_rows == 60 and rec.participants.num_rows == 3
    assert rec.meta.start_time == "2024-05-13T08:15:00.000000001Z"
    report = aveas_format.validate(FROZEN[version])
    assert report.counts["error"] == 0, report.flatten(("code", "message"))


def test_every_known_version_has_a_frozen_example():
    assert set(versions.KNOWN_VERSIONS) == set(FROZEN)


@pytest.fixture
def old_version(tmp_path, monkeypatch):
    """A made-up 0.9.0 predecessor: `acquisition.institution` and states column `pos_x` were
    renamed to `acquisition.partner` and `x` in 1.0.0. Registers the migration step for the test."""
    def meta_step(meta):
        meta["acquisition"]["partner"] = meta["acquisition"].pop("institution")
        return meta

    def states_step(table):
        return table.rename_columns(["x" if c == "pos_x" else c for c in table.column_names])

    monkeypatch.setitem(versions.MIGRATIONS, ("0.9.0", "1.0.0"), meta_step)
    monkeypatch.setitem(versions.TABLE_MIGRATIONS, ("0.9.0", "1.0.0"), {"states": states_step})
    path = tmp_path / "old.aveas"
    shutil.copytree(FROZEN["1.0.0"], path)
    states = pq.read_table(path / "states.parquet")
    key = json.loads(states.schema.metadata[b"aveas"])
    key["format_version"] = "0.9.0"
    states = states.rename_columns(["pos_x" if c == "x" else c for c in states.column_names])
    states = states.replace_schema_metadata({b"aveas": json.dumps(key).encode()})
    pq.write_table(states, path / "states.parquet")
    meta = json.loads((path / "recording.json").read_text())
    meta["format_version"] = "0.9.0"
    meta["acquisition"]["institution"] = meta["acquisition"].pop("partner")
    meta["tables"]["states"]["sha256"] = hashlib.sha256((path / "states.parquet").read_bytes()).hexdigest()
    (path / "recording.json").write_text(json.dumps(meta))
    return path


def test_old_version_is_migrated_in_memory(old_version):
    rec = aveas_format.open(old_version)
    assert rec.migrated_from == "0.9.0"
    assert rec.meta.format_version == "1.0.0"
    assert rec.meta.acquisition.partner == "test"
    assert "x" in rec.states.column_names and "pos_x" not in rec.states.column_names
    assert json.loads((old_version / "recording.json").read_text())["format_version"] == "0.9.0"
    assert rec.summary()["migrated_from"] == "0.9.0"


def test_migrated_recording_is_written_at_the_current_version(old_version, tmp_path):
    rec = aveas_format.open(old_version)
    out = rec.write(tmp_path / "new.aveas")
    assert json.loads((out / "recording.json").read_text())["format_version"] == "1.0.0"
    assert aveas_format.open(out).migrated_from is None


def test_migration_path_rules(monkeypatch):
    assert versions.migration_path("1.0.0") == []
    assert versions.migration_path("1.2.0") == []  # newer minor of the same major: read as is
    monkeypatch.setitem(versions.MIGRATIONS, ("0.8.0", "0.9.0"), lambda m: m)
    monkeypatch.setitem(versions.MIGRATIONS, ("0.9.0", "1.0.0"), lambda m: m)
    assert versions.migration_path("0.8.0") == [("0.8.0", "0.9.0"), ("0.9.0", "1.0.0")]
    with pytest.raises(versions.VersionError, match="newer than this library"):
        versions.migration_path("2.0.0")
