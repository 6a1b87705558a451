"""Figures (matplotlib): the map with lanes and trajectories, histograms, report figures."""

from aveas_format.plot.figures import (
    acceleration_histogram,
    figures,
    map_figure,
    png_bytes,
    sample_rate_figure,
    save_figures,
    speed_histogram,
)

__all__ = ["acceleration_histogram", "figures", "map_figure", "png_bytes", "sample_rate_figure",
           "save_figures", "speed_histogram"]
