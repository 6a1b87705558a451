"""A second ``kinematics`` derivation."""

from __future__ import annotations

from aveas_format.derive.registry import Derivation, Params, register


class P(Params):
    """No parameters."""


register(Derivation(name="kinematics", table="events", version="1", params=P,
                    fn=lambda rec, p: None, needs={}, doc="not the real one"))
