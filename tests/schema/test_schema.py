"""The schema layer: enums, taxonomy, PMF models, recording.json model, column declarations."""

from __future__ import annotations

import json
import subprocess
import sys

import jsonschema
import numpy as np
import pytest
from pydantic import ValidationError

from aveas_format.schema import CLASSES, TABLES, RecordingMeta, recording_json_schema, tables_spec
from aveas_format.schema.columns import Column, TableSpec
from aveas_format.schema.enums import Requirement
from aveas_format.schema.metadata import WeatherPmf, timestamp_ns
from aveas_format.schema.pmf import argmax, normalise, one_hot, pmf_problems

from helpers_common import minimal_meta

AVEAS_OPENLABEL_ORDER = ["animal", "bicycle", "bus", "car", "pedestrian", "mobility_device",
                         "motorcycle", "other", "pushable_pullable", "railvehicle", "trailer",
                         "truck", "van"]


def test_taxonomy_is_aveas_openlabel_order():
    assert list(CLASSES) == AVEAS_OPENLABEL_ORDER


def test_minimal_meta_is_valid_and_round_trips():
    m = RecordingMeta.model_validate(minimal_meta())
    again = RecordingMeta.model_validate_json(m.to_json())
    assert again == m


@pytest.mark.parametrize("where", [(), ("acquisition",), ("rights",), ("location",)])
def test_unknown_keys_rejected_everywhere(where):
    d = minimal_meta()
    target = d
    for k in where:
        target = target[k]
    target["surprise"] = 1
    with pytest.raises(ValidationError, match="surprise"):
        RecordingMeta.model_validate(d)


def test_extras_take_free_keys():
    m = RecordingMeta.model_validate(minimal_meta(extras={"anything": {"nested": [1, 2]}}))
    assert m.extras["anything"]["nested"] == [1, 2]


@pytest.mark.parametrize("field,value", [
    ("provenance", "synthetic"),
    ("acquisition", {"method": "satellite", "partner": "x"}),
    ("rights", {"right_of_use": "public", "license": "x", "owner": "y"}),
    ("start_time", "2024-05-13 08:15:00"),
    ("start_time", "2024-02-30T00:00:00Z"),
    ("duration_s", -1),
    ("nominal_rate_hz", 0),
    ("format_version", "1.0"),
    ("location", {"lon": 200, "lat": 0}),
])
def test_invalid_values_rejected(field, value):
    with pytest.raises(ValidationError):
        RecordingMeta.model_validate(minimal_meta(**{field: value}))


def test_nanosecond_timestamps():
    m = RecordingMeta.model_validate(minimal_meta(start_time="2024-05-13T08:15:00.123456789+00:00"))
    assert m.start_time == "2024-05-13T08:15:00.123456789Z"
    assert timestamp_ns(m.start_time) % 1_000_000_000 == 123456789


def test_pmf_model_checks_sum_and_sign():
    assert WeatherPmf(clear=0.5, rain=0.5).argmax() in ("clear", "rain")
    with pytest.raises(ValidationError, match="sum to 1"):
        WeatherPmf(clear=0.5, rain=0.4)
    with pytest.raises(ValidationError):
        WeatherPmf(clear=1.2, rain=-0.2)
    assert WeatherPmf(clear=0.9995).clear == 0.9995  # within 1e-3
    assert WeatherPmf.one_hot("fog").fog == 1.0


def test_pmf_helpers():
    m = one_hot(["car", "truck", "van"], "class")
    assert m.shape == (3, 13) and m.dtype == np.float32
    assert list(argmax(m, "class")) == ["car", "truck", "van"]
    bad = m.copy()
    bad[1, 0] = 0.5
    bad[2] = np.nan  # a null row is unknown, not invalid
    assert list(pmf_problems(bad)) == [False, True, False]
    assert np.allclose(normalise(np.array([[2.0, 2.0], [0.0, 0.0]])), [[0.5, 0.5], [0.5, 0.5]])
    with pytest.raises(ValueError, match="unknown class category 'spaceship'"):
        one_hot(["spaceship"], "class")


def test_json_schema_validates_conformance_metadata(conformance_path):
    schema = recording_json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    data = json.loads((conformance_path / "recording.json").read_text())
    jsonschema.validate(data, schema)
    bad = dict(data, provenance="made_up")
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, schema)


def test_every_table_is_declared_consistently():
    for name, spec in TABLES.items():
        assert spec.name == name
        assert spec.file == f"{name}.parquet"
        for k in spec.key + spec.sort:
            assert k in spec, (name, k)
        for c in spec.columns:
            assert c.doc, (name, c.name)
            if c.name.endswith("_std"):
                assert c.qualifies and c.qualifies[0] in spec and c.minimum == 0.0
    assert TABLES["states"].column("lane_id").type == "int16"
    assert TABLES["participants"].column("class_pmf").pmf_categories == tuple(AVEAS_OPENLABEL_ORDER)


def test_table_spec_rejects_bad_declarations():
    with pytest.raises(ValueError, match="unknown logical type"):
        Column("a", "float128", Requirement.MAY, "doc")
    with pytest.raises(ValueError, match="unknown PMF category set"):
        Column("a", "pmf<colours>", Requirement.MAY, "doc")
    c = Column("a", "int64", Requirement.MAY, "doc")
    with pytest.raises(ValueError, match="duplicate"):
        TableSpec("t", "t.parquet", Requirement.MAY, "doc", (c, c))


def test_tables_spec_is_json():
    spec = json.loads(json.dumps(tables_spec()))
    names = [t["name"] for t in spec["tables"]]
    assert names[:2] == ["participants", "states"] and "derived/kinematics" in names
    length = next(c for c in spec["tables"][0]["columns"] if c["name"] == "length")
    assert length["unit"] == "m" and length["range"] == "> 0" and length["requirement"] == "MUST"


def test_schema_layer_imports_no_heavy_io_libraries():
    code = ("import sys, aveas_format.schema, aveas_format.schema.docs; "
            "print(sorted(m for m in ('pyarrow', 'lxml', 'pyproj') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "[]"
