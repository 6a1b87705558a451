"""A new derivation writing the table of ``kinematics``."""

from __future__ import annotations

from aveas_format.derive.registry import Derivation, Params, register
from aveas_format.schema.columns import pid_col, time_col
from aveas_format.schema.tables import derived_table


class P(Params):
    """No parameters."""


register(Derivation(name="kinematics_again", spec=derived_table("kinematics", "not the real one",
                                                                (pid_col(), time_col())),
                    version="1", params=P, fn=lambda rec, p: None, needs={},
                    doc="not the real one"))
