"""Property-based fuzzing of the readers: broken input gives a clear library error (AveasError)
or findings, never an unexpected exception.

Every input that once crashed a reader is kept, minimised, under tests/data/fuzz/<reader>/ and
replayed here forever.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import aveas_format
from aveas_format.errors import AveasError
from aveas_format.opendrive import load_map

from helpers_common import DATA, STRAIGHT_MAP, small_recording
from helpers_fuzz import OPS, mutate

FUZZ = DATA / "fuzz"
SETTINGS = settings(max_examples=int(__import__("os").environ.get("AVEAS_FUZZ_EXAMPLES", "40")), deadline=None,
                    derandomize=not __import__("os").environ.get("AVEAS_FUZZ_EXAMPLES"),
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])


def _expect_clean(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except AveasError:
        return None


# --- OpenDRIVE ------------------------------------------------------------------------------------

@SETTINGS
@given(ops=OPS)
def test_load_map_on_mutated_maps(ops):
    data = mutate(STRAIGHT_MAP.read_bytes(), ops)
    net = _expect_clean(load_map, data)
    if net is not None:  # a map that still parses must also survive the engine's queries
        import numpy as np

        net.world_to_road(np.array([10.0, 500.0]), np.array([-1.0, -5.0]))
        net.check()


# --- recordings -------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def base_recording(tmp_path_factory):
    return small_recording(n=3, steps=30).write(tmp_path_factory.mktemp("fz") / "base.aveas")


MEMBERS = ["recording.json", "participants.parquet", "states.parquet", "map.xodr"]


@SETTINGS
@given(member=st.sampled_from(MEMBERS), ops=OPS)
def test_open_and_validate_mutated_recordings(tmp_path_factory, base_recording, member, ops):
    path = tmp_path_factory.mktemp("m") / "r.aveas"
    shutil.copytree(base_recording, path)
    f = path / member
    f.write_bytes(mutate(f.read_bytes(), ops))
    _expect_clean(aveas_format.open, path)
    _expect_clean(aveas_format.open, path, verify=False)
    report = _expect_clean(aveas_format.validate, path)
    if report is not None:
        assert report.failures == [], [x.error for x in report.failures]


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-10**12, 10**12) | st.floats(allow_nan=True)
    | st.text(max_size=20),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=8), children,
                                                                      max_size=3),
    max_leaves=8)


@SETTINGS
@given(path_keys=st.lists(st.sampled_from(
    ["format_version", "start_time", "duration_s", "nominal_rate_hz", "acquisition", "provenance",
     "location", "crs", "map", "coverage", "rights", "conditions", "thresholds", "tables",
     "derived", "source", "extras", "title"]), min_size=1, max_size=3), value=JSON_VALUES)
def test_structurally_wrong_metadata(tmp_path_factory, base_recording, path_keys, value):
    path = tmp_path_factory.mktemp("j") / "r.aveas"
    shutil.copytree(base_recording, path)
    meta = json.loads((path / "recording.json").read_text())
    for k in path_keys:
        meta[k] = value
    (path / "recording.json").write_text(json.dumps(meta, allow_nan=True))
    _expect_clean(aveas_format.open, path)
    report = _expect_clean(aveas_format.validate, path)
    if report is not None:
        assert report.failures == [], [x.error for x in report.failures]


# --- the crash corpus ---------------------------------------------------------------------------

def _corpus(kind: str) -> list[Path]:
    d = FUZZ / kind
    return sorted(d.iterdir()) if d.is_dir() else []


@pytest.mark.parametrize("path", _corpus("xodr"), ids=lambda p: p.name)
def test_corpus_maps(path):
    _expect_clean(load_map, path.read_bytes())


@pytest.mark.parametrize("path", _corpus("recordings"), ids=lambda p: p.name)
def test_corpus_recordings(path):
    _expect_clean(aveas_format.open, path)
    report = _expect_clean(aveas_format.validate, path)
    if report is not None:
        assert report.failures == []


# --- hostile values in well-formed tables -------------------------------------------------------

HOSTILE_FLOATS = st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e300, -1e300, 0.0,
                                  -0.0, 5e-324, 1.0])


@SETTINGS
@given(n=st.integers(0, 6), column=st.sampled_from(
    ["time", "x", "y", "heading", "vx", "vy", "lon", "lat", "x_std", "road_s", "road_t"]),
    values=st.lists(HOSTILE_FLOATS, min_size=6, max_size=6), same_times=st.booleans(),
    weird_ids=st.booleans())
def test_hostile_values_give_findings_not_crashes(tmp_path_factory, n, column, values, same_times,
                                                  weird_ids):
    """NaN / inf / 1e300, empty tables, single samples, identical times, control characters in ids:
    validate reports findings and never crashes (no tool failure)."""
    import hashlib

    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path_factory.mktemp("h") / "r.aveas"
    rec = small_recording(n=2, steps=3)
    rec.write(path)
    t = pq.read_table(path / "states.parquet")
    md = t.schema.metadata
    t = t.slice(0, n)
    if n:
        arr = np.asarray(values[:n], dtype=np.float64)
        t = t.set_column(t.column_names.index(column), column, pa.array(arr))
        if same_times:
            t = t.set_column(t.column_names.index("time"), "time", pa.array(np.zeros(n)))
    pq.write_table(t.replace_schema_metadata(md), path / "states.parquet")
    meta = json.loads((path / "recording.json").read_text())
    meta["tables"]["states"] = {"rows": t.num_rows, "sha256": hashlib.sha256(
        (path / "states.parquet").read_bytes()).hexdigest()}
    if weird_ids:
        p = pq.read_table(path / "participants.parquet")
        pmd = p.schema.metadata
        p = p.set_column(p.column_names.index("source_id"), "source_id",
                         pa.array(["\x00\x1b[31m☠\u202e", ""]))
        pq.write_table(p.replace_schema_metadata(pmd), path / "participants.parquet")
        meta["tables"]["participants"]["sha256"] = hashlib.sha256(
            (path / "participants.parquet").read_bytes()).hexdigest()
    (path / "recording.json").write_text(json.dumps(meta))
    _expect_clean(aveas_format.open, path)
    report = _expect_clean(aveas_format.validate, path)
    assert report is not None
    assert report.failures == [], [x.error for x in report.failures]
