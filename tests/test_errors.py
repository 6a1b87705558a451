"""The error helpers of aveas_format.errors: report_source warns by default and collects when asked."""

import warnings

import pytest

from aveas_format.errors import SourceFinding, collect_source_findings, report_source


def test_report_source_warns_without_a_listener():
    with pytest.warns(UserWarning, match="3 boxes dropped"):
        report_source("source.openlabel.bad_size", "3 boxes dropped", frame="7", count=3)


def test_report_source_collects_located_findings_when_listened_to():
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # nothing may be warned while collected
        with collect_source_findings() as found:
            report_source("source.openlabel.bad_size", "dropped", frame="7", uid="12", count=3,
                          json_path=None)
            with collect_source_findings() as inner:      # nested: the innermost listener wins
                report_source("source.osi.x", "inner", message_index=4)
    assert found == [SourceFinding("source.openlabel.bad_size", "dropped",
                                   {"frame": "7", "uid": "12"}, 3)]
    assert [f.location for f in inner] == [{"message_index": 4}]
    with pytest.warns(UserWarning):            # the listener is gone after the block
        report_source("source.x", "after")
