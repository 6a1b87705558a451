"""Partner CSV: one row per participant and time with columns ``id,time,x,y`` (seconds; metres in
the map's local frame); every participant is a car of the length and width given as options."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.converters.common import read_numeric_table, sort_states, wrap_recording
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes


class PartnerCsvOptions(ImportOptions):
    """Options of partner-csv."""

    length: float = 4.5
    """Length of every participant (m)."""
    width: float = 1.8
    """Width of every participant (m)."""


@converter("partner-csv", description="Partner CSV trajectories (id,time,x,y)", patterns=("*.csv",),
           method="aerial", options=PartnerCsvOptions)
def convert_partner_csv(inputs: list[Path], *, map_source, options: PartnerCsvOptions):
    t = read_numeric_table(inputs[0], required=("id", "time", "x", "y"),
                           numeric=("id", "time", "x", "y"))
    ids, time = column_numpy(t, "id").astype(np.int64), column_numpy(t, "time")
    order = sort_states(ids, time, inputs[0], np.arange(len(ids)) + 2)  # CSV line of each row
    ids, time = ids[order], time[order]
    uniq, pid = np.unique(ids, return_inverse=True)
    n = len(uniq)
    participants = {"participant_id": np.arange(n, dtype=np.int64),
                    "source_id": [str(i) for i in uniq], "class": ["car"] * n,
                    "length": np.full(n, options.length), "width": np.full(n, options.width)}
    states = {"participant_id": pid.astype(np.int64), "time": time,
              "x": column_numpy(t, "x")[order], "y": column_numpy(t, "y")[order]}
    return wrap_recording("partner-csv", inputs, options, map_bytes=load_map_bytes(map_source),
                          participants=participants, states=states, partner="partner",
                          method="aerial")
