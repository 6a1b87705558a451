"""The presentation layer: every figure (matplotlib) and the HTML validation report.

One module per subject; each takes data (tables, arrays, a Report, a RoadNetwork) and draws, and
none imports ``fit``, ``sim`` or ``dataset`` (they sit above and call in). Figures are standalone
``matplotlib.figure.Figure`` objects (no pyplot state, headless) written atomically with
:func:`aveas_format.safeio.save_figure_atomic`.

- :mod:`~aveas_format.plot.map`: an OpenDRIVE map, lanes filled by type, reference lines, road
  and junction ids (``plot_map``, ``save_map``; ``aveas-format map plot``).
- :mod:`~aveas_format.plot.recording`: figures of a recording: the map with trajectories by class,
  direction of travel, coverage, unobserved regions and located findings (a marker per rule);
  speed and signed longitudinal acceleration histograms per class over robust ranges; sample rate
  (``aveas-format plot``).
- :mod:`~aveas_format.plot.report_html`: the self-contained HTML validation report with those
  figures (``aveas-format validate --format html``).
- :mod:`~aveas_format.plot.derive`: time series of derived tables with 1-sigma bands (TTC,
  accelerations; the figures of docs/derive.md).
- :mod:`~aveas_format.plot.fit`: the fitter's figures (histogram vs simulated density, start/end
  parameters per restart).
- :mod:`~aveas_format.plot.sensitivity`: the W99 sensitivity study's figure.

matplotlib is the ``[plot]`` extra: a module that draws at import (``derive``, ``fit``,
``sensitivity``) or a function that draws (``plot_map``, the recording figures) says so in one line
naming the extra (:func:`aveas_format.errors.require`); the HTML report renders without it, minus
the figures, and says which extra draws them.

The names below are re-exported lazily (on first use), so importing one module, e.g.
``aveas_format.plot.map``, does not load the others (the HTML report loads the validator).
"""

from __future__ import annotations

import importlib
from typing import Any


_MODULES: dict[str, tuple[str, ...]] = {
    "derive": ("acceleration_figure", "ttc_figure"),
    "fit": ("plot_histogram", "plot_parameters"),
    "map": ("BACKGROUND_LANE_COLORS", "LANE_COLORS", "plot_map", "save_map"),
    "recording": ("CLASS_COLORS", "acceleration_histogram", "figures", "longitudinal_acceleration",
                  "map_figure", "open_for_figures", "png_bytes", "recording_name", "robust_range",
                  "sample_rate_figure", "save_figures", "speed_histogram"),
    "report_html": ("render_html", "report_figures"),
    "sensitivity": ("plot_sensitivity",),
}
_HOME = {name: module for module, names in _MODULES.items() for name in names}


def __getattr__(name: str) -> Any:
    if name in _HOME:
        value = getattr(importlib.import_module(f"aveas_format.plot.{_HOME[name]}"), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'aveas_format.plot' has no attribute {name!r}")


__all__ = sorted(_HOME)
