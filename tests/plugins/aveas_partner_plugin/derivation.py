"""``derived/partner_speed``: the speed over ground of every state, from its velocity."""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.schema.columns import MUST, gaussian, pid_col, time_col
from aveas_format.schema.tables import derived_table


class PartnerSpeedParams(Params):
    """Parameters of ``partner_speed`` (none)."""


def compute(rec, params: PartnerSpeedParams) -> pa.Table:
    s = rec.states
    vx, vy = s.column("vx").to_numpy(), s.column("vy").to_numpy()
    return pa.table({"participant_id": s.column("participant_id"), "time": s.column("time"),
                     "speed": pa.array(np.hypot(vx, vy)),
                     "speed_std": pa.nulls(len(s), pa.float64())})


TABLE = derived_table(
    "partner_speed",
    doc="Speed over ground per participant and time, from the velocity of the states.",
    key=("participant_id", "time"),
    sort=("participant_id", "time"),
    columns=(pid_col(), time_col(), *gaussian("speed", "m/s", MUST, "speed over ground",
                                              minimum=0.0)),
)

PARTNER_SPEED = register(Derivation(
    name="partner_speed",
    spec=TABLE,
    version="1.0.0",
    params=PartnerSpeedParams,
    fn=compute,
    needs={"states": ("participant_id", "time", "vx", "vy")},
    doc="speed over ground from the states' velocity",
    method=lambda p: "hypot",
))
