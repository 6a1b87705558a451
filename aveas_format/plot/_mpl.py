"""matplotlib, the ``[plot]`` extra, for the modules that draw at import: importing ``Figure``
from here gives the one-line message naming the extra when it is missing
(:func:`aveas_format.errors.require`), in one place."""

from __future__ import annotations

from aveas_format.errors import require

require("matplotlib", extra="plot", what="figures")

from matplotlib.figure import Figure  # noqa: E402  (after the message of the missing extra)

__all__ = ["Figure"]
