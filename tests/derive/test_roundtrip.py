"""derive -> write -> open: derived tables present and valid, provenance and staleness."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest

import aveas_format
from aveas_format.derive import DERIVED_KEY, criticality_summary, derive, stale_derived
from aveas_format.derive.traffic import local_density
from aveas_format.errors import FormatError
from aveas_format.sample import highway_scene


@pytest.fixture(scope="module")
def derived_scene():
    rec = highway_scene(n_vehicles=30, duration_s=12.0)
    ran = derive(rec)
    return rec, ran


def test_all_derivations_run(derived_scene):
    rec, ran = derived_scene
    assert set(ran) == {"kinematics", "interactions", "encroachments", "traffic", "events",
                        "conflicts", "criticality_summary"}
    assert ran.index("kinematics") < ran.index("interactions") < ran.index("events")
    assert set(rec.derived) == {"kinematics", "interactions", "encroachments", "traffic",
                                "conflicts", "criticality_summary"}
    entries = {e.table: e for e in rec.meta.derived}
    assert set(entries) == {f"derived/{n}" for n in rec.derived}
    k = entries["derived/kinematics"]
    assert k.method == "ca_kalman_rts" and k.version and "states" in k.inputs
    assert "derived/kinematics" in entries["derived/interactions"].inputs
    info = json.loads(rec.derived["kinematics"].schema.metadata[DERIVED_KEY])
    assert info["parameters"]["jerk_density"] == "auto"


def test_write_open_validate(tmp_path, derived_scene):
    rec, _ = derived_scene
    path = rec.write(tmp_path / "d.aveas")
    back = aveas_format.open(path)
    assert set(back.derived) == set(rec.derived)
    for n, t in rec.derived.items():
        assert back.derived[n].num_rows == t.num_rows
    assert stale_derived(back) == []
    report = aveas_format.validate(path)
    errors = [r for r in report.results if r.severity.value == "error"]
    assert not errors, errors
    assert not [r for r in report.results if r.code == "metadata.derived_stale"]
    # the scene's events (if any: lane-keeping and a few lane changes) come back as derived
    # events with their metric (the events of true conflicts: test_near_miss)
    ev = back.events.to_pylist() if back.events is not None else []
    assert all(e["origin"] == "derived" for e in ev)
    assert all(e["metric"] == json.loads(e["attributes"])["metric"] in ("ttc", "pet", "a_lon")
               for e in ev)


def test_staleness_after_input_change(tmp_path):
    rec = highway_scene(n_vehicles=10, duration_s=4.0)
    derive(rec, only=["kinematics", "traffic"])
    assert stale_derived(rec) == []
    s = rec.states
    rec.states = s.set_column(s.column_names.index("x"), "x",
                              pa.array(s.column("x").to_numpy() + 0.01))
    assert stale_derived(rec) == ["derived/kinematics", "derived/traffic"]  # in memory
    path = rec.write(tmp_path / "s.aveas")
    back = aveas_format.open(path)
    assert stale_derived(back) == ["derived/kinematics", "derived/traffic"]  # as validate sees it
    report = aveas_format.validate(path)
    assert [r.count for r in report.results if r.code == "metadata.derived_stale"] == [2]
    derive(back, only=["kinematics", "traffic"])
    assert stale_derived(back) == []


def test_params_routed_and_unknown_rejected():
    rec = highway_scene(n_vehicles=8, duration_s=4.0)
    derive(rec, only="traffic", cell_duration_s=2.0)
    assert {r["time_end"] - r["time_start"] for r in rec.derived["traffic"].to_pylist()} == {2.0}
    with pytest.raises(FormatError, match="unknown parameter"):
        derive(rec, only="traffic", no_such_option=1)
    with pytest.raises(FormatError, match="unknown derivation"):
        derive(rec, only="nope")
    with pytest.raises(FormatError, match="cell_length_m"):
        derive(rec, only="traffic", cell_length_m=-1)


def test_events_keep_annotations_and_summary():
    rec = highway_scene(n_vehicles=30, duration_s=12.0)
    rec.events = pa.table({
        "event_id": pa.array([5], pa.int64()), "kind": ["lane_change"],
        "time_start": [1.0], "time_end": [2.0], "participant_ids": [[3]],
        "origin": ["annotated"]})
    derive(rec, ttc_s=2.0)
    ev = rec.events.to_pylist()
    assert ev[0]["event_id"] == 5 and ev[0]["origin"] == "annotated"
    derived = [e for e in ev if e["origin"] == "derived"]
    assert all(e["event_id"] > 5 for e in derived)
    for e in derived:
        a = json.loads(e["attributes"])
        if a["metric"] == "ttc":
            assert a["threshold_s"] == 2.0 and a["min_value_s"] <= 2.0
    s = criticality_summary(rec)
    assert s["near_misses"] == sum(e["kind"] == "near_miss" for e in derived)
    if s["min_ttc_s"] is not None:
        it = rec.derived["interactions"].column("ttc").to_numpy(zero_copy_only=False)
        assert s["min_ttc_s"]["value"] == pytest.approx(np.nanmin(it.astype(float)))


def test_local_density():
    rec = highway_scene(n_vehicles=20, duration_s=4.0)
    d = local_density(rec, radius_m=50.0)
    assert d.num_rows == rec.states.num_rows
    c = d.column("local_count").to_numpy(zero_copy_only=False)
    dens = d.column("local_density").to_numpy(zero_copy_only=False)
    ok = np.isfinite(dens.astype(float))
    assert np.allclose(dens[ok], c[ok] / 100.0 * 1000.0)
