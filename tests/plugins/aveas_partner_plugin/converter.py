"""Partner CSV: one row per participant and time with columns ``id,time,x,y`` (seconds; metres in
the map's local frame); every participant is a car of the length and width given as options.

A converter as a partner writes one (docs/extending.md): read and map the source into box
columns, describe the sensor, hand both to the shared step."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.converters.common import Boxes, Rows, Sensor, read_table, to_recording
from aveas_format.converters.registry import ImportOptions, converter
from aveas_format.io.arrow import column_numpy
from aveas_format.mapref.build import load_map_bytes


class PartnerCsvOptions(ImportOptions):
    """Options of partner-csv."""

    length: float = 4.5
    """Length of every participant (m)."""
    width: float = 1.8
    """Width of every participant (m)."""


def _is_partner_csv(path: Path, head: bytes) -> bool:
    """A CSV whose header is ``id,time,x,y``."""
    return head.split(b"\n", 1)[0].strip().replace(b" ", b"") == b"id,time,x,y"


@converter("partner-csv", description="Partner CSV trajectories (id,time,x,y)", patterns=("*.csv",),
           method="aerial", options=PartnerCsvOptions, sniff=_is_partner_csv)
def convert_partner_csv(inputs: list[Path], *, map_source, options: PartnerCsvOptions):
    t = read_table(inputs[0], required=("id", "time", "x", "y"), numeric=("id", "time", "x", "y"))
    uniq, pid = np.unique(column_numpy(t, "id").astype(np.int64), return_inverse=True)
    boxes = Boxes(pid, column_numpy(t, "time"), column_numpy(t, "x"), column_numpy(t, "y"),
                  source_ids=[str(i) for i in uniq],
                  rows=Rows(inputs, place=np.arange(t.num_rows) + 2))  # the CSV line of each row
    n = len(uniq)
    return to_recording(boxes, Sensor(method="aerial", platform="partner drone", partner="partner"),
                        converter="partner-csv", inputs=inputs, options=options,
                        map_bytes=load_map_bytes(map_source),
                        participants={"class": ["car"] * n, "length": np.full(n, options.length),
                                      "width": np.full(n, options.width)})
