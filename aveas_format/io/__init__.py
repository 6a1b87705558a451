"""Recordings on disk <-> in memory: directory and ZIP forms, atomic writes, partial reads."""

from aveas_format.io.arrow import arrow_schema, conform, pmf_array, pmf_matrix
from aveas_format.io.reader import ReadPlan, open_recording, read_meta
from aveas_format.io.recording import Recording
from aveas_format.io.writer import write_recording

__all__ = [
    "ReadPlan", "Recording", "arrow_schema", "conform", "open_recording",
    "pmf_array", "pmf_matrix", "read_meta", "write_recording",
]
