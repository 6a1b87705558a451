"""Structure rules: each is caught by exactly the intended rule; the valid recording yields nothing."""

from __future__ import annotations

import hashlib
import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import aveas_format
from aveas_format.validate import REGISTRY, Hit, load_rules, rule
from aveas_format.validate.registry import select_rules


def _meta(path):
    return json.loads((path / "recording.json").read_text())


def _set_meta(path, meta):
    (path / "recording.json").write_text(json.dumps(meta, indent=2))


def _rewrite(path, table, fn, fix=True):
    """Rewrite a table file with fn(table), keeping its 'aveas' key; fix recording.json's entry."""
    p = path / f"{table}.parquet"
    t = pq.read_table(p)
    md = t.schema.metadata
    t = fn(t)
    if t.schema.metadata is None and md is not None:
        t = t.replace_schema_metadata(md)
    pq.write_table(t, p)
    if fix:
        meta = _meta(path)
        meta["tables"][table] = {"rows": t.num_rows,
                                 "sha256": hashlib.sha256(p.read_bytes()).hexdigest()}
        _set_meta(path, meta)


def _set_col(t, name, arr):
    if name in t.column_names:
        return t.set_column(t.column_names.index(name), name, arr)
    return t.append_column(name, arr)


def _np_set(t, name, rows, value):
    a = t.column(name).to_numpy().copy()
    a[rows] = value
    return _set_col(t, name, pa.array(a))


def m_missing_states(p):
    (p / "states.parquet").unlink()


def m_broken_json(p):
    (p / "recording.json").write_text('{\n  "format_version": "1.0.0",\n  oops\n}')


def m_format_version(p):
    meta = _meta(p)
    meta["format_version"] = "7.0.0"
    _set_meta(p, meta)


def m_metadata_schema(p):
    meta = _meta(p)
    meta["provenance"] = "synthetic"
    _set_meta(p, meta)


def m_metadata_semantic(p):  # passes the JSON Schema, fails the model: a PMF that sums to 0.5
    meta = _meta(p)
    meta["conditions"] = {"weather": {"clear": 0.5}}
    _set_meta(p, meta)


def m_unlisted(p):
    meta = _meta(p)
    del meta["tables"]["participants"]
    _set_meta(p, meta)


def m_unknown_table(p):
    meta = _meta(p)
    meta["tables"]["trajectories"] = {"rows": 0, "sha256": "0" * 64}
    _set_meta(p, meta)


def m_checksum(p):
    meta = _meta(p)
    meta["tables"]["states"]["sha256"] = "f" * 64
    _set_meta(p, meta)


def m_row_count(p):
    meta = _meta(p)
    meta["tables"]["states"]["rows"] = 3
    _set_meta(p, meta)


def m_unreadable(p):
    f = p / "states.parquet"
    f.write_bytes(f.read_bytes()[:100])
    meta = _meta(p)
    meta["tables"]["states"]["sha256"] = hashlib.sha256(f.read_bytes()).hexdigest()
    _set_meta(p, meta)


def m_parquet_key(p):
    _rewrite(p, "participants", lambda t: t.replace_schema_metadata({b"other": b"1"}))


def m_missing_column(p):
    _rewrite(p, "states", lambda t: t.drop_columns(["lat"]))


def m_column_type(p):
    _rewrite(p, "states", lambda t: _set_col(t, "vx", t.column("vx").cast(pa.string())))


def m_unknown_column(p):
    _rewrite(p, "states", lambda t: t.append_column("my_flag", pa.array(np.zeros(t.num_rows))))


def m_null_values(p):
    _rewrite(p, "states", lambda t: _np_set(t, "x", [5], np.nan))


def m_value_range(p):
    _rewrite(p, "participants", lambda t: _np_set(t, "length", [2], -4.0))


def m_category(p):
    def f(t):
        cls = t.column("class").cast(pa.string()).to_pylist()
        cls[1] = "spaceship"
        return _set_col(t, "class", pa.array(cls).dictionary_encode())
    _rewrite(p, "participants", f)


def m_pmf(p):
    def f(t):
        m = np.zeros((t.num_rows, 13), np.float32)
        m[:, 3] = 1.0
        m[0, 3] = 0.7
        from aveas_format.io.arrow import pmf_array
        return _set_col(t, "class_pmf", pmf_array(m, "class"))
    _rewrite(p, "participants", f)


def m_sort_order(p):
    _rewrite(p, "states", lambda t: t.take(pa.array(np.r_[1, 0, np.arange(2, t.num_rows)])))


def m_duplicate_key(p):
    _rewrite(p, "states", lambda t: _np_set(t, "time", [1], 0.0))


CASES = [
    (m_missing_states, [["structure.missing_file", None, None]]),
    (m_broken_json, [["structure.broken_json", None, None]]),
    (m_format_version, [["structure.format_version", None, None]]),
    (m_metadata_schema, [["structure.metadata_schema", None, None]]),
    (m_metadata_semantic, [["structure.metadata_schema", None, None]]),
    (m_unlisted, [["structure.unlisted_table", None, None]]),
    (m_unknown_table, [["structure.unknown_table", None, None]]),
    (m_checksum, [["structure.checksum", None, None]]),
    (m_row_count, [["structure.row_count", None, None]]),
    (m_unreadable, [["structure.unreadable_table", None, None]]),
    (m_parquet_key, [["structure.parquet_key", None, None]]),
    (m_missing_column, [["structure.missing_column", None, None]]),
    (m_column_type, [["structure.column_type", None, None]]),
    (m_unknown_column, [["structure.unknown_column", None, None]]),
    (m_null_values, [["structure.null_values", 5, 0]]),
    (m_value_range, [["structure.value_range", 2, 2]]),
    (m_category, [["structure.category", 1, 1]]),
    (m_pmf, [["structure.pmf", 0, 0]]),
    (m_sort_order, [["structure.sort_order", 0, 0]]),
    (m_duplicate_key, [["structure.duplicate_key", 1, None]]),
]


def test_valid_recording_has_no_findings(written):
    report = aveas_format.validate(written, select=["structure"])
    assert report.flatten() == [] and report.failures == []
    full = aveas_format.validate(written)  # the other families find only warnings (sizes, SHOULDs)
    assert full.failures == [] and full.counts["error"] == 0
    assert full.exit_code() == 0


@pytest.mark.parametrize("mutate,expected", CASES, ids=[c[0].__name__ for c in CASES])
def test_each_rule_catches_its_case(written, mutate, expected):
    mutate(written)
    report = aveas_format.validate(written, select=["structure"])
    assert report.failures == []
    got = [f for f in report.flatten(("code", "row", "participant_id"))]
    assert got == expected, [f.message for f in report.findings()]
    assert report.exit_code("error") == (1 if report.counts["error"] else 0)


def test_every_structure_rule_has_a_failing_case():  # the other families: test_rule_corpus.py
    covered = {e[0][0] for _, e in CASES}
    structure = {c for c in load_rules() if c.startswith("structure.")}
    assert structure == covered


def test_registry_enforces_its_declarations():
    for r in load_rules().values():
        assert r.doc and r.title and r.message
        assert r.severity.value in ("error", "warning", "info")
        if r.severity.value == "error":
            assert r.enforces, f"{r.code}: an error rule must name the MUST it enforces"
        if r.severity.value == "warning":
            assert r.enforces and "SHOULD" in r.enforces, f"{r.code}: name the SHOULD it enforces"
    with pytest.raises(ValueError, match="must name the MUST"):
        rule("structure.new_error", "error", "t", "m")
    with pytest.raises(ValueError, match="must name the SHOULD"):
        rule("structure.new_warning", "warning", "t", "m")
    with pytest.raises(ValueError, match="names none"):
        rule("structure.new_warning", "warning", "t", "m", enforces="FORMAT.md 1: something")
    with pytest.raises(ValueError, match="family.snake_case"):
        rule("NoFamily", "error", "t", "m")
    with pytest.raises(ValueError, match="registered twice"):
        rule("structure.checksum", "error", "t", "m")


def test_counts_are_complete_and_samples_bounded(written):
    _rewrite(written, "states", lambda t: _np_set(t, "x", np.arange(120), np.nan))
    report = aveas_format.validate(written, select=["structure.null_values"], max_sample=10)
    (res,) = report.results
    assert res.count == 120 and len(res.sample) == 10 and res.truncated
    f = res.sample[3]
    assert f.location.row == 3 and f.location.column == "x" and f.location.table == "states"
    assert f.message == "states.parquet: row 3: x is null"


def test_a_crashing_rule_is_a_tool_failure(written):
    @rule("zzz.crash_for_test", "warning", "crash", "never", enforces="a test rule SHOULD crash")
    def crash(ctx):
        """Raises on purpose."""
        raise RuntimeError("boom")
        yield Hit()

    try:
        report = aveas_format.validate(written)
        assert [f.code for f in report.failures] == ["zzz.crash_for_test"]
        assert "RuntimeError: boom" in report.failures[0].error
        assert report.exit_code() == 3
        assert report.counts["error"] == 0
    finally:
        del REGISTRY["zzz.crash_for_test"]


def test_select_and_ignore():
    codes = {r.code for r in select_rules(["structure"], ["structure.checksum"])}
    assert "structure.checksum" not in codes and "structure.pmf" in codes
    with pytest.raises(ValueError, match="unknown rule or family"):
        select_rules(["nonsense"])


def test_validate_in_memory_recording(rec):
    report = aveas_format.validate(rec)
    assert report.counts["error"] == 0


def test_zip_form_is_validated(tmp_path, rec):
    z = rec.write(tmp_path / "v.aveas.zip")
    assert aveas_format.validate(z, select=["structure"]).flatten() == []


@pytest.mark.parametrize("form", ["directory", "zip"])
def test_clean_recording_on_disk_has_no_finding(tmp_path, clean, form):
    """Every rule, reading from disk (checksums, Parquet keys...): the clean recording is clean."""
    path = clean.write(tmp_path / ("c.aveas.zip" if form == "zip" else "c.aveas"))
    report = aveas_format.validate(path)
    assert report.failures == [] and report.flatten(("code", "message")) == []
