"""The OpenLABEL import's findings about the source (issue 22): each is a ``report_source`` with
its code and the source's location (file, frame key, object uid, JSON path, count) — collected
when a caller listens (``aveas-format validate FILE``), a warning otherwise."""

from __future__ import annotations

import json
import warnings

import pytest
from helpers_common import STRAIGHT_MAP

from aveas_format.converters import convert, get_converter
from aveas_format.converters.registry import UnstatedWarning
from aveas_format.errors import collect_source_findings
from aveas_format.sample import highway_scene


def _obj(x: float, *, vel: bool = True, acc: bool = True, size: float = 4.0, extra_vec=(), cs=None):
    cub = {"name": "bounding_box", "val": [x, -1.75, 0.75, 0, 0, 0, size, 1.8, 1.5]}
    if cs:
        cub["coordinate_system"] = cs
    vec = ([{"name": "velocity", "val": [10.0, 0, 0, 0, 0, 0]}] if vel else []) + \
          ([{"name": "acceleration", "val": [0.0, 0, 0, 0, 0, 0]}] if acc else []) + list(extra_vec)
    return {"object_data": {"cuboid": [cub], "vec": vec}}


def _profile_doc() -> dict:
    """A small file that claims the AVEAS profile, with one of each defect."""
    pmf_bad = {"name": "operator/focussed_object/uncertainties", "val": [0.5, 0.4]}
    frames = {
        "0": {"frame_properties": {"timestamp": 0.0},
              "objects": {"1": _obj(0.0), "2": _obj(10.0, acc=False, extra_vec=[pmf_bad])}},
        "1": {"frame_properties": {"timestamp": 0.1},
              "objects": {"1": _obj(1.0), "2": _obj(11.0, acc=False, size=-1000.0)}},
        "2": {"frame_properties": {"timestamp": 0.1},  # repeats frame 1's time: a duplicate state
              "objects": {"1": _obj(1.5, cs="lidar_top")}},
        "3": {"frame_properties": {"timestamp": 0.2}, "objects": {"1": _obj(2.0), "2": _obj(12.0)}},
    }
    class_pmf = [0.0] * 13
    class_pmf[3] = 0.9  # sums to 0.9
    objects = {
        "1": {"name": "car1", "type": "vehicle/car",
              "object_data": {"vec": [{"name": "dimensions/size", "val": [4.0, 1.8, 1.5]}]}},
        "2": {"name": "thing2", "type": "vehicle/gizmo",
              "object_data": {"vec": [{"name": "classification/uncertainties", "val": class_pmf}]}},
    }
    return {"openlabel": {"metadata": {"schema_version": "1.0.0", "acquisition_method": "aerial",
                                       "acquisition_date": "last tuesday"},
                          "coordinate_systems": {"odr": {"type": "scene_cs", "parent": "",
                                                         "children": []}},
                          "objects": objects, "frames": frames}}


@pytest.fixture
def profile_file(tmp_path):
    p = tmp_path / "submission.json"
    p.write_text(json.dumps(_profile_doc()))
    return p


def _by_code(found) -> dict[str, list]:
    out: dict[str, list] = {}
    for f in found:
        out.setdefault(f.code, []).append(f)
    return out


def test_findings_are_collected_with_their_location(profile_file):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # collected, not warned
        warnings.simplefilter("ignore", UnstatedWarning)  # (no partner, licence, start time: said once)
        with collect_source_findings() as found:
            rec = convert("openlabel", [profile_file], map_source=STRAIGHT_MAP)
    by = _by_code(found)
    file = str(profile_file)
    assert all(f.location["file"] == file for f in found)

    (bad,) = by["source.openlabel.bad_size"]
    assert (bad.location["frame"], bad.location["uid"], bad.count) == ("1", "2", 1)
    assert bad.location["json_path"] == "$.openlabel.frames['1'].objects['2'].object_data.cuboid"

    (dup,) = by["source.openlabel.duplicate_state"]
    assert (dup.location["frame"], dup.location["uid"], dup.count) == ("2", "1", 1)

    (cs,) = by["source.openlabel.unknown_coordinate_system"]
    assert (cs.location["frame"], cs.location["uid"]) == ("2", "1") and "'lidar_top'" in cs.message

    pmf = {f.location.get("frame"): f for f in by["source.openlabel.pmf_sum"]}
    assert (pmf["0"].location["uid"], pmf["0"].count) == ("2", 1)  # the box's attribute
    assert "operator/focussed_object/uncertainties" in pmf["0"].message
    assert pmf[None].location["uid"] == "2" and "classification" in pmf[None].message  # the object's

    miss = {f.location.get("frame"): f for f in by["source.openlabel.missing_attribute"]}
    # object 2 lacks its acceleration in frames 0 and 1 (frame 1's box is dropped later: the check
    # is on the source), and its dimensions/size
    assert (miss["0"].location["uid"], miss["0"].count) == ("2", 2) and "'acceleration'" in miss["0"].message
    assert miss[None].location["uid"] == "2" and "dimensions/size" in miss[None].message

    (typ,) = by["source.openlabel.unknown_type"]
    assert (typ.location["uid"], typ.count) == ("2", 1) and "'vehicle/gizmo'" in typ.message
    assert typ.location["json_path"] == "$.openlabel.objects['2'].type"

    (md,) = by["source.openlabel.bad_metadata"]
    assert md.location["json_path"] == "$.openlabel.metadata.acquisition_date"
    # the import itself went on: 3 boxes of object 1 (one duplicate dropped) + 2 of object 2
    assert rec.states.num_rows == 5


def test_without_a_listener_each_finding_is_a_warning(profile_file):
    with pytest.warns(UserWarning) as got:
        convert("openlabel", [profile_file], map_source=STRAIGHT_MAP)
    text = "\n".join(str(w.message) for w in got)
    for part in ("sentinel or impossible size", "repeat a (participant, time)", "'lidar_top'",
                 "do not sum to 1", "mandatory attribute 'acceleration'", "'vehicle/gizmo'",
                 "acquisition_date 'last tuesday'"):
        assert part in text


def test_a_clean_export_has_no_findings(tmp_path):
    rec = highway_scene(n_vehicles=3, duration_s=2.0)
    out = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, out)
    with collect_source_findings() as found:
        convert("openlabel", [out])
    assert found == []


def test_skipped_extension_entries_are_located(tmp_path):
    rec = highway_scene(n_vehicles=3, duration_s=2.0)
    out = tmp_path / "rec.json"
    get_converter("openlabel", "export")(rec, out)
    doc = json.loads(out.read_text())
    ext = doc["openlabel"]["metadata"]["aveas_format"]
    ext.setdefault("derived", {})["no_such_table"] = {"columns": {}}
    ext["derived_entries"] = [*ext.get("derived_entries", []), {"name": 3}]
    out.write_text(json.dumps(doc))
    with collect_source_findings() as found:
        convert("openlabel", [out])
    paths = sorted(f.location["json_path"] for f in found if f.code == "source.openlabel.extension_skipped")
    n = len(ext["derived_entries"]) - 1
    assert paths == ["$.openlabel.metadata.aveas_format.derived['no_such_table']",
                     f"$.openlabel.metadata.aveas_format.derived_entries[{n}]"]


# --- the compact forms (.json.gz, .json.zst) ------------------------------------------------------

@pytest.mark.parametrize("suffix", [".json.gz", ".json.zst"])
def test_compact_forms_round_trip_as_the_plain_file(tmp_path, suffix):
    import gzip

    if suffix == ".json.zst":
        zstandard = pytest.importorskip("zstandard", reason="the [zstd] extra")
    rec = highway_scene(n_vehicles=3, duration_s=2.0)
    plain, small = tmp_path / "rec.json", tmp_path / f"small{suffix}"
    get_converter("openlabel", "export")(rec, plain)
    get_converter("openlabel", "export")(rec, small)
    assert (tmp_path / "small.xodr").is_file()  # the map's name without the compression suffix
    raw = small.read_bytes()
    text = gzip.decompress(raw) if suffix == ".json.gz" else \
        zstandard.ZstdDecompressor().stream_reader(raw).read()
    assert json.loads(text)["openlabel"]["frames"] == json.loads(plain.read_bytes())["openlabel"]["frames"]
    assert len(raw) < plain.stat().st_size / 4
    a, b = convert("openlabel", [plain]), convert("openlabel", [small])
    assert a.states.equals(b.states) and a.participants.equals(b.participants)


def test_a_broken_compressed_file_is_a_clear_error(tmp_path):
    import aveas_format

    rec = highway_scene(n_vehicles=2, duration_s=1.0)
    p = tmp_path / "rec.json.gz"
    get_converter("openlabel", "export")(rec, p)
    p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])  # truncated
    with pytest.raises(aveas_format.FormatError) as ei:
        convert("openlabel", [p])
    assert str(p) in str(ei.value)


def test_a_decompression_bomb_stops_at_the_size_limit(tmp_path, monkeypatch):
    import aveas_format
    from aveas_format.safeio import compressed

    rec = highway_scene(n_vehicles=2, duration_s=1.0)
    p = tmp_path / "rec.json.gz"
    get_converter("openlabel", "export")(rec, p)
    monkeypatch.setattr(compressed, "MAX_STREAMED_JSON_BYTES", 2 * p.stat().st_size)  # < the plain size
    with pytest.raises(aveas_format.FormatError, match="once decompressed exceeds the limit") as ei:
        convert("openlabel", [p])
    assert str(p) in str(ei.value)


def test_odd_attribute_values_are_no_internal_error(tmp_path):
    # a velocity that is a number, a dict and a ragged list; an item without a name; a name that
    # is no text: the import goes on (NaN where no vector), as box by box it would
    doc = _profile_doc()
    objs = doc["openlabel"]["frames"]["3"]["objects"]
    objs["1"]["object_data"]["vec"][0]["val"] = 5
    objs["2"]["object_data"]["vec"] = [{"name": "velocity", "val": {"x": 1}}, {"val": [1]},
                                       {"name": 7, "val": [1]}]
    doc["openlabel"]["frames"]["0"]["objects"]["1"]["object_data"]["vec"][0]["val"] = [9.0, 0.5]
    p = tmp_path / "odd.json"
    p.write_text(json.dumps(doc))
    with collect_source_findings():
        rec = convert("openlabel", [p], map_source=STRAIGHT_MAP)
    assert rec.states.num_rows == 5
