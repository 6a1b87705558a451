"""Eclipse SUMO runner: scenarios (the paper's autobahn by default), runs, simulated recordings.

>>> from aveas_format.sim import Scenario, simulate
>>> res = simulate(Scenario.from_toml("scenario.toml"), recording=True)   # doctest: +SKIP

Needs SUMO: ``pip install "aveas-format[sim]"`` (the ``eclipse-sumo`` wheel) or ``SUMO_HOME``.
"""

from __future__ import annotations

from aveas_format.sim.runner import (
    SimResult,
    SimulationError,
    SumoNotFoundError,
    build_network,
    fcd_mean_speeds,
    find_sumo,
    prepare_network,
    section_mean_speeds,
    simulate,
)
from aveas_format.sim.scenario import W99_DEFAULTS, W99_RANGES, Network, Scenario, VehicleClass

__all__ = ["W99_DEFAULTS", "W99_RANGES", "Network", "Scenario", "SimResult", "SimulationError",
           "SumoNotFoundError", "VehicleClass", "build_network", "fcd_mean_speeds", "find_sumo",
           "prepare_network", "section_mean_speeds", "simulate"]
