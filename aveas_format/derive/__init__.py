"""Derivations (FORMAT.md section 10): kinematics, interactions, encroachments, traffic, events.

>>> from aveas_format.derive import derive, stale_derived, criticality_summary
>>> derive(rec)                       # all derivations, in dependency order   # doctest: +SKIP
>>> derive(rec, only="kinematics", jerk_density=2.0)                          # doctest: +SKIP

Each derivation lives in its own module (``encroachments``, ``events``, ``traffic``) or subpackage
(``interactions``, ``kinematics``: the ``__init__`` registers, private ``_*`` modules hold the
helpers), declares the spec of the table it writes there and registers itself in :mod:`.registry`;
the modules are found by :mod:`aveas_format.plugins` (no list to edit; partner packages add theirs
through entry points, docs/extending.md). :mod:`._samples` holds what several derivations share
(the states rows as arrays, road coordinates, track segments). The definitions, conventions and
uncertainty methods are documented in ``docs/derive.md``.
"""

from __future__ import annotations

from aveas_format.derive.registry import (
    DERIVED_KEY,
    REGISTRY,
    Derivation,
    Params,
    derivations,
    derive,
    stale_derived,
    table_sha256,
)


def criticality_summary(rec):  # noqa: D103 — re-exported below
    from aveas_format.derive.events import criticality_summary as f

    return f(rec)


criticality_summary.__doc__ = "Per-recording criticality summary (see :mod:`.events`)."

__all__ = ["DERIVED_KEY", "REGISTRY", "Derivation", "Params", "criticality_summary", "derivations",
           "derive", "stale_derived", "table_sha256"]
