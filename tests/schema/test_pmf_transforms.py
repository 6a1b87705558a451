"""PMFs stay normalised through every transform (STYLE.md 12): the conversion helpers and the
build funnel every converter goes through, writing and reading, the OpenLABEL round trip and a
version migration."""

from __future__ import annotations

import json
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import aveas_format
from aveas_format.converters import convert, get_converter
from aveas_format.converters.labels import class_pmf
from aveas_format.io.arrow import pmf_array, pmf_matrix
from aveas_format.schema import versions
from aveas_format.schema.pmf import argmax, normalise, pmf_problems
from aveas_format.schema.taxonomy import CLASSES, PMF_TOLERANCE

from helpers_common import small_recording

K = len(CLASSES)
SETTINGS = settings(max_examples=25, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@st.composite
def pmf_rows(draw, n: int) -> np.ndarray:
    """n PMF rows over the 13 classes: one-hot, near-one-hot with tiny mass elsewhere, spread, or
    raw weights of very different magnitudes, normalised as a converter would."""
    rows = []
    for _ in range(n):
        kind = draw(st.sampled_from(["one_hot", "tiny", "spread"]))
        w = np.zeros(K)
        top = draw(st.integers(0, K - 1))
        if kind == "one_hot":
            w[top] = 1.0
        elif kind == "tiny":
            w[:] = draw(st.floats(1e-9, 1e-4))
            w[top] = 1.0
        else:
            w = np.array(draw(st.lists(st.floats(0.0, 1e6), min_size=K, max_size=K)))
            w[top] += 1e-3  # never all zero
        rows.append(w)
    return normalise(np.array(rows))


def _assert_normalised(m: np.ndarray, where: str) -> None:
    assert m.shape[1] == K
    assert not np.isnan(m).any(), f"{where}: a PMF became null"
    bad = pmf_problems(m)
    assert not bad.any(), f"{where}: rows {np.flatnonzero(bad).tolist()} sum to {m.sum(axis=1)[bad]}"


def _fresh(tmp_path) -> Path:
    """A new directory per hypothesis example (tmp_path is shared by the examples of one test)."""
    return Path(tempfile.mkdtemp(dir=tmp_path))


def _with_pmf(pm: np.ndarray):
    rec = small_recording(n=len(pm))
    p = rec.participants
    i = p.column_names.index("class")
    cls = pa.array(argmax(pm, "class").tolist()).cast(p.schema.field("class").type)
    p = p.set_column(i, "class", cls)
    if "class_pmf" in p.column_names:
        p = p.drop_columns(["class_pmf"])
    rec.replace_tables({"participants": p.append_column("class_pmf", pmf_array(pm, "class"))})
    return rec


@given(labels=st.lists(st.sampled_from(CLASSES), min_size=1, max_size=20),
       confidence=st.floats(0.0, 1.0))
def test_hard_labels_with_a_confidence_are_normalised(labels, confidence):
    pm = class_pmf(labels, confidence)
    _assert_normalised(pm, "converters.labels.class_pmf")
    if confidence > 1.0 / K + 1e-6:
        assert argmax(pm, "class").tolist() == labels


@SETTINGS
@given(data=st.data())
def test_build_write_read_keep_pmfs(data, tmp_path):
    pm = data.draw(pmf_rows(4))
    rec = _with_pmf(pm)
    got = pmf_matrix(rec.participants.column("class_pmf"), "class")
    _assert_normalised(got, "in memory")
    out = rec.write(_fresh(tmp_path) / "r.aveas")
    back = aveas_format.open(out)
    m = pmf_matrix(back.participants.column("class_pmf"), "class")
    _assert_normalised(m, "written and read")
    np.testing.assert_array_equal(m, pm.astype(np.float32))
    assert back.participants.column("class").to_pylist() == argmax(m, "class").tolist()


@SETTINGS
@given(data=st.data())
def test_openlabel_round_trip_keeps_pmfs(data, tmp_path):
    pm = data.draw(pmf_rows(4))
    rec = _with_pmf(pm)
    out = _fresh(tmp_path) / "rec.json"
    get_converter("openlabel", "export")(rec, out, options={})
    back = convert("openlabel", [out])
    m = pmf_matrix(back.participants.column("class_pmf"), "class")
    _assert_normalised(m, "OpenLABEL round trip")
    np.testing.assert_allclose(m, pm, atol=PMF_TOLERANCE / K)
    assert back.participants.column("class").to_pylist() == argmax(pm, "class").tolist()


@pytest.fixture
def as_0_9_0(monkeypatch):
    """Register the made-up 0.9.0 -> 1.0.0 step of tests/schema/test_versions.py (a renamed metadata key)
    and return a function that turns a written 1.0.0 recording into a 0.9.0 one."""
    def meta_step(meta):
        meta["acquisition"]["partner"] = meta["acquisition"].pop("institution")
        return meta

    monkeypatch.setitem(versions.MIGRATIONS, ("0.9.0", "1.0.0"), meta_step)
    monkeypatch.setitem(versions.TABLE_MIGRATIONS, ("0.9.0", "1.0.0"), {})

    def downgrade(path):
        import hashlib

        for f in path.glob("*.parquet"):
            t = pq.read_table(f)
            key = json.loads(t.schema.metadata[b"aveas"])
            key["format_version"] = "0.9.0"
            pq.write_table(t.replace_schema_metadata({**t.schema.metadata,
                                                      b"aveas": json.dumps(key).encode()}), f)
        meta = json.loads((path / "recording.json").read_text())
        meta["format_version"] = "0.9.0"
        meta["acquisition"]["institution"] = meta["acquisition"].pop("partner")
        for name, entry in meta["tables"].items():
            entry["sha256"] = hashlib.sha256((path / f"{name}.parquet").read_bytes()).hexdigest()
        (path / "recording.json").write_text(json.dumps(meta))
        return path

    return downgrade


@SETTINGS
@given(data=st.data())
def test_migration_keeps_pmfs(data, tmp_path, as_0_9_0):
    pm = data.draw(pmf_rows(3))
    path = _fresh(tmp_path) / "m.aveas"
    _with_pmf(pm).write(path)
    as_0_9_0(path)
    rec = aveas_format.open(path)
    assert rec.migrated_from == "0.9.0"
    m = pmf_matrix(rec.participants.column("class_pmf"), "class")
    _assert_normalised(m, "migrated from 0.9.0")
    np.testing.assert_array_equal(m, pm)
    shutil.rmtree(path)
