"""The Report as pandas users expect it: to_pandas, a short repr, facts as properties, no pydantic
methods on the public surface, JSON unchanged."""

from __future__ import annotations

import json
import pickle

import pytest

import aveas_format
import helpers_validate as vf
from aveas_format.validate.report import Report, Severity, report_json_schema


@pytest.fixture(scope="module")
def report():
    sc = vf.fresh()
    sc["tracks"][0]["x"][75:] += 3.0          # kinematics.position_jump (error)
    sc["participants"]["length"][1] = 9.0      # participants.size_implausible (warning)
    return aveas_format.validate(vf.build(sc))


def test_to_pandas_one_row_per_finding_with_typed_locations(report):
    pd = pytest.importorskip("pandas")
    df = report.to_pandas()
    assert len(df) == len(report.findings()) == 2
    assert list(df.columns[:4]) == ["code", "severity", "title", "message"]
    assert str(df["row"].dtype) == "Int64" and str(df["participant_id"].dtype) == "Int64"
    assert str(df["time"].dtype) == "Float64" and str(df["table"].dtype) == "string"
    assert isinstance(df["severity"].dtype, pd.CategoricalDtype) and df["severity"].cat.ordered
    assert df[df.severity >= "error"]["code"].tolist() == ["kinematics.position_jump"]
    jump = df.set_index("code").loc["kinematics.position_jump"]
    assert (jump["row"], jump["participant_id"], jump["column"]) == (75, 0, "x,y")
    assert jump["time"] == pytest.approx(3.0)
    assert pd.isna(df.set_index("code").loc["participants.size_implausible", "time"])
    assert isinstance(jump["context"], dict)
    empty = aveas_format.validate(vf.build(vf.fresh())).to_pandas()
    assert len(empty) == 0 and list(empty.columns) == list(df.columns)


def test_repr_is_short(report):
    r = repr(report)
    assert r.startswith("<Report 'validate-clean': INVALID: 1 errors, 1 warnings, 0 info; top: "
                        "kinematics.position_jump (1), participants.size_implausible (1)>")
    assert len(r) < 300 and "sample=" not in r and "Finding(" not in r
    assert "<table>" in report._repr_html_()


def test_facts_are_properties(report):
    assert report.counts == {"error": 1, "warning": 1, "info": 0}
    assert report.max_severity is Severity.ERROR
    assert report.codes == {"kinematics.position_jump", "participants.size_implausible"}
    assert report.status == "invalid"
    assert report.exit_code == 1 and isinstance(report.exit_code, int)
    assert report.exit_code("warning") == 1 and report.exit_code("never") == 0  # thresholds
    # the former method spellings still work where that is cheap
    assert report.codes() == report.codes and report.exit_code() == 1


def test_no_pydantic_internals_on_the_public_surface(report):
    public = {n for n in dir(report) if not n.startswith("_")}
    assert not public & {"validate", "model_dump", "model_validate", "construct", "copy", "dict",
                         "json", "parse_obj", "schema", "model_fields", "model_config"}
    assert public >= {"counts", "exit_code", "max_severity", "codes", "findings", "flatten",
                      "to_json", "to_dict", "to_pandas", "results", "failures", "recording"}


def test_json_round_trips_and_matches_its_schema(report):
    import jsonschema

    text = report.to_json()
    jsonschema.Draft202012Validator(report_json_schema()).validate(json.loads(text))
    assert set(json.loads(text)) == {"recording", "format_version", "tool_version", "rules_run",
                                     "results", "failures", "seconds", "streamed"}
    back = Report.from_json(text)
    assert back == report and back.to_json() == text and back.to_dict() == json.loads(text)
    assert pickle.loads(pickle.dumps(report)) == report
