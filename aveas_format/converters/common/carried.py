"""The recording.json values an export carries so that its re-import asks for nothing, and how
an import takes them back.

A person states the partner, the licence and the start time of a recording (``convert -O``); an
export into a foreign format writes them where the format has a place (OpenSCENARIO: the
``FileHeader``'s ``License`` and ``Properties``; an OSI MCAP trace: a metadata record; OpenLABEL:
its metadata) and the import of that file reads them back into the
:class:`~aveas_format.converters.common.boxes.Sensor` as the source's own values, which the import
options still override.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: the values carried (keys as the metadata of the foreign file names them, ``aveas:`` prefixed
#: where they share a namespace with the file's own, as OpenSCENARIO properties)
CARRIED = ("partner", "license", "owner", "right_of_use", "start_time", "title")
#: the stand-ins of a recording whose source states no value (the validator flags them)
STAND_INS = {"partner": "unknown", "license": "unspecified", "start_time": "1970-01-01T00:00:00Z"}


def carried_meta(rec) -> dict[str, str]:
    """The values of :data:`CARRIED` a recording has (stand-ins left out: nothing to carry)."""
    m = rec.meta
    values = {"partner": m.acquisition.partner, "license": m.rights.license,
              "owner": m.rights.owner, "right_of_use": getattr(m.rights.right_of_use, "value",
                                                              m.rights.right_of_use),
              "start_time": m.start_time, "title": m.title}
    return {k: str(v) for k, v in values.items()
            if v not in (None, "") and STAND_INS.get(k) != str(v)}


def sensor_values(values: Mapping[str, Any]) -> dict[str, str]:
    """The :class:`~aveas_format.converters.common.boxes.Sensor` keyword arguments of carried
    values read back (unknown keys and empty values ignored)."""
    return {k: str(values[k]) for k in CARRIED if values.get(k) not in (None, "")}


def stand_ins(meta) -> list[str]:
    """Which of partner, licence and start time a recording's ``meta`` has only as a stand-in
    (a simulation's start time at the epoch is none: it has no calendar date)."""
    got = {"partner": meta.acquisition.partner, "license": meta.rights.license,
           "start_time": meta.start_time}
    simulated = str(getattr(meta.acquisition.method, "value", meta.acquisition.method)) in (
        "traffic_simulation", "driving_simulator")
    return [k for k, v in got.items()
            if (str(v).startswith("1970-01-01T00:00:00") if k == "start_time" else str(v) == STAND_INS[k])
            and not (k == "start_time" and simulated)]
