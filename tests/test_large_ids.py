"""Integer ids are int64 everywhere: a recording whose ids need all 64 bits (2**60 + 1 is a valid
participant id) validates, derives and draws exactly as the same recording with small ids.

float64 holds integers exactly only up to 2**53: 2**60 + 1, 2**60 + 2 and 2**60 + 3 are one number
there, so any float cast of an id column merges participants (or, in pyarrow, raises ArrowInvalid).
Cross-cutting (validate, derive, plot), hence at the top of tests/.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pyarrow as pa
import pytest

import aveas_format
import helpers_validate as vf

BIG = [2**60 + 1, 2**60 + 2, 2**60 + 3, 2**63 - 1]  # the first three are one float64
SMALL = [0, 1, 2, 3]


def _recording(ids: list[int], region: int):
    sc = vf.fresh()
    sc["track_ids"] = ids
    sc["participants"]["participant_id"] = np.array(ids, np.int64)
    # a truck towing nothing: attached_to names no participant (4, or 2**60 + 5: float-equal to
    # participant 2**60 + 1); the occlusion is caused by the third participant
    sc["participants"]["attached_to"] = pa.array([None, None, ids[0] + 4, None], pa.int64())
    sc["unobserved"]["region_id"] = np.array([region], np.int64)
    sc["unobserved"]["occluder_id"] = np.array([ids[2]], np.int64)
    return vf.build(sc)


@pytest.fixture(scope="module")
def pair():
    return _recording(SMALL, 0), _recording(BIG, 2**61 + 7)


def _relabel(value, mapping: dict[int, int]):
    return mapping.get(value, value) if isinstance(value, int) else value


def test_validate_finds_the_same_with_64_bit_ids(pair):
    small, big = pair
    rs, rb = aveas_format.validate(small), aveas_format.validate(big)
    assert rb.failures == [] and rs.failures == []
    assert rb.codes == rs.codes == {"participants.attached_to_unknown"}
    (f,) = rb.findings()
    assert f.location.participant_id == BIG[2] and f.context["value"] == BIG[0] + 4
    back = dict(zip(BIG, SMALL)) | {BIG[0] + 4: SMALL[0] + 4}
    assert [[_relabel(v, back) for v in row] for row in
            rb.flatten(("code", "row", "participant_id", "value"))] == \
        rs.flatten(("code", "row", "participant_id", "value"))


def test_value_range_and_references_work_on_64_bit_ids():
    """structure.value_range (which crashed with ArrowInvalid) checks int64 columns in their own
    type: a negative 64-bit id is found; an unknown 64-bit occluder is named exactly."""
    big = _recording(BIG, 2**61 + 7)
    vf.set_column(big, "participants", "participant_id",
                  pa.array([BIG[0], BIG[1], -(2**62), BIG[3]], pa.int64()))
    vf.set_column(big, "unobserved", "occluder_id", pa.array([2**60 + 5], pa.int64()))
    report = aveas_format.validate(big, select=["structure.value_range",
                                                "participants.unknown_reference"])
    assert report.failures == []
    by = {r.code: r for r in report.results}
    (vr,) = by["structure.value_range"].sample
    assert (vr.location.column, vr.location.row, vr.context["value"]) == \
        ("participant_id", 2, -(2**62))
    (ref,) = by["participants.unknown_reference"].sample
    assert ref.location.participant_id == 2**60 + 5


def test_cli_validate_of_64_bit_ids_is_not_a_tool_failure(pair, tmp_path):
    _, big = pair
    path = big.write(tmp_path / "big.aveas")
    res = subprocess.run([sys.executable, "-m", "aveas_format", "validate", str(path)],
                         capture_output=True, text=True, timeout=300)
    assert res.returncode == 1, res.stdout + res.stderr  # the attached_to error, no crash
    assert "participants.attached_to_unknown" in res.stdout
    assert f"participant {BIG[2]} is attached_to {BIG[0] + 4}" in res.stdout


def test_derive_keeps_64_bit_ids():
    """Every derivation gives the same tables, ids relabelled; no two participants merge."""
    from aveas_format.derive import derive

    small, big = (_recording(SMALL, 0), _recording(BIG, 2**61 + 7))
    derive(small)
    derive(big)
    assert set(big.derived) == set(small.derived) and "interactions" in big.derived
    fwd = dict(zip(SMALL, BIG))
    for name, ts in small.derived.items():
        tb = big.derived[name]
        assert tb.num_rows == ts.num_rows, name
        for col in tb.column_names:
            if col in ("participant_id", "other_id", "first_id", "second_id"):
                assert tb.column(col).type == pa.int64()
                want = [fwd.get(v, v) for v in ts.column(col).to_pylist()]
                assert tb.column(col).to_pylist() == want, (name, col)
    pids = big.derived["kinematics"].column("participant_id").to_pylist()
    assert set(pids) == set(BIG)


def test_figures_draw_64_bit_ids(pair):
    """The figures of the big-id recording equal those of the small one (same samples per
    participant in the sample-rate curve, the same trajectories)."""
    from aveas_format.plot.recording import figures

    small, big = pair
    fs, fb = figures(small), figures(big)
    assert set(fs) == set(fb)
    for name in ("sample_rate", "map"):
        ls = [line.get_xydata() for line in fs[name].axes[0].get_lines()]
        lb = [line.get_xydata() for line in fb[name].axes[0].get_lines()]
        assert len(ls) == len(lb) and all(np.array_equal(a, b, equal_nan=True)
                                          for a, b in zip(ls, lb)), name


def test_derivation_figures_select_exactly_one_64_bit_participant():
    """The TTC and acceleration figures pick a participant by its exact id: 2**60 + 1 and
    2**60 + 2 are one float64, yet only one of them is drawn."""
    from aveas_format.derive import derive
    from aveas_format.plot.derive import acceleration_figure

    big = _recording(BIG, 2**61 + 7)
    derive(big, only="kinematics")
    ax = acceleration_figure(big.derived["kinematics"], BIG[0]).axes[0]
    n = int((np.asarray(big.derived["kinematics"].column("participant_id")) == BIG[0]).sum())
    assert n == 150 and max(len(line.get_xdata()) for line in ax.get_lines()) == n
