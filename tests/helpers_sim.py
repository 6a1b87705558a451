"""Helpers of the SUMO runner and fitter tests (tests/sim, tests/fit)."""

from __future__ import annotations

from aveas_format.sim import Network, Scenario, VehicleClass

PAPER = {"car": (131.05, 17.48), "truck": (89.22, 6.20)}
#: fitting bounds around the paper's estimates (km/h)
NARROW = {"mu_car": (115.0, 150.0), "sigma_car": (8.0, 28.0), "mu_truck": (80.0, 100.0),
          "sigma_truck": (2.0, 12.0)}


def small_scenario(duration: float = 300.0, seed: int = 1, length: float = 1000.0, inflow: float = 300.0,
                   **kw) -> Scenario:
    """The paper's demand and desired speeds on a shorter road."""
    return Scenario(network=Network(length=length, inflow=inflow), duration=duration, seed=seed, classes=[
        VehicleClass(name="car", flow=1680, speed_mean_kmh=PAPER["car"][0], speed_std_kmh=PAPER["car"][1]),
        VehicleClass(name="truck", vclass="truck", flow=320, speed_mean_kmh=PAPER["truck"][0],
                     speed_std_kmh=PAPER["truck"][1])], **kw)


def cli_simulated_recording(folder, toml: str):
    """Write the scenario ``toml`` to ``folder/s.toml`` and run ``aveas-format sim run`` on it into
    ``folder/rec.aveas`` (no validation); returns both paths."""
    import pytest

    from aveas_format.cli import main

    cfg = folder / "s.toml"
    cfg.write_text(toml)
    with pytest.raises(SystemExit) as e:
        main(["sim", "run", "-c", str(cfg), "-o", str(folder / "rec.aveas"), "-O", "license=CC0-1.0",
              "--no-validate"])
    assert e.value.code == 0
    return cfg, folder / "rec.aveas"
