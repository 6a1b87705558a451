"""``aveas-format sim``: run SUMO scenarios into recordings; the W99 TTC sensitivity study."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors, out
from aveas_format.cli.options import (
    ask_unstated,
    check_output,
    check_output_dir,
    converter_options,
    option_pairs_option,
    options_file_option,
    overwrite_option,
    scheduler_option,
    validate_option,
    validate_written,
    workers_option,
)

sim_app = typer.Typer(help="Simulate traffic with Eclipse SUMO (needs `pip install "
                      "\"aveas-format[sim]\"`).", no_args_is_help=True)
app.add_typer(sim_app, name="sim")


def _scenario(config: Path | None, seed: int | None, duration: float | None):
    from aveas_format.sim.scenario import Scenario

    sc = Scenario.from_toml(config) if config else Scenario()
    upd = {}
    if seed is not None:
        upd["seed"] = seed
    if duration is not None:
        upd["duration"] = duration
    return sc.model_copy(update=upd) if upd else sc


@sim_app.command("run")
@handle_errors
def run(
    config: Path = typer.Option(None, "--config", "-c", help="Scenario TOML (docs/fitting.md); "
                                "default: the paper's autobahn."),
    output: Path = typer.Option(..., "--output", "-o", help="Output recording (NAME.aveas or "
                                ".aveas.zip)."),
    seed: int = typer.Option(None, "--seed", help="Override the scenario's seed."),
    duration: float = typer.Option(None, "--duration", help="Override the demand period (s)."),
    workdir: Path = typer.Option(None, "--workdir", help="Keep SUMO's files here (default: a "
                                 "temporary directory)."),
    option: list[str] = option_pairs_option("Recording (sumo-fcd import)"),
    options_file: Path = options_file_option("Recording (sumo-fcd import)"),
    overwrite: bool = overwrite_option(),
    validate_: bool = validate_option(help="Validate the result."),
) -> None:
    """Run a scenario with SUMO and write the result as a recording: `aveas-format sim run --config
    scenario.toml -o sim.aveas -O license=CC-BY-4.0`. The licence of the result is yours to state
    (`-O license=...`, asked for before SUMO runs); the partner is "aveas-format sim" unless
    `-O partner=...` names another."""
    from aveas_format.converters.registry import get_converter
    from aveas_format.sim.runner import simulate

    conv = get_converter("sumo-fcd")
    raw = {"partner": "aveas-format sim", **converter_options(options_file, option, conv.options)}
    conv.parse_options(raw)  # usage errors (an unknown option, the licence unstated) first
    ask_unstated(conv, raw)
    check_output(output, overwrite)
    sc = _scenario(config, seed, duration)
    res = simulate(sc, recording=True, workdir=workdir, recording_options=raw)
    path = res.recording.write(output, overwrite=overwrite)
    ms = res.mean_speeds()
    err.print(f"wrote {path}: {res.recording.participants.num_rows} vehicles, "
              f"{res.recording.states.num_rows:,} states ({res.runtime_s:.1f} s of SUMO)")
    for c, v in ms.items():
        if len(v):
            err.print(f"  {c}: {len(v)} vehicles on the measurement section, mean speed "
                      f"{v.mean():.1f} km/h (sd {v.std(ddof=1) if len(v) > 1 else 0:.1f})")
    if validate_:
        validate_written(path)


@sim_app.command("sensitivity")
@handle_errors
def sensitivity_cmd(
    config: Path = typer.Option(None, "--config", "-c", help="Base scenario TOML (default: the "
                                "paper's autobahn)."),
    output: Path = typer.Option(..., "--output", "-o", help="Output directory (sensitivity.json, "
                                "sensitivity.png)."),
    param: list[str] = typer.Option(None, "--param", "-p", help="W99 parameter to vary "
                                    "(repeatable; default cc0..cc9)."),
    values: int = typer.Option(5, "--values", "-n", min=2, help="Values per parameter over its range."),
    fraction: float = typer.Option(0.2, "--fraction", help="Share of the cars that get the varied "
                                   "parameter."),
    duration: float = typer.Option(None, "--duration", help="Override the demand period (s) "
                                   "(the paper: 4 h)."),
    workers: int = workers_option(),
    scheduler: str = scheduler_option(help="Dask scheduler address tcp://..."),
    overwrite: bool = overwrite_option(help="Replace the files of an existing OUTPUT directory."),
    min_ttc_samples: int = typer.Option(1, "--min-ttc-samples", min=1, help="TTC samples a vehicle "
                                        "needs for its mean TTC to count in the minimum mean TTC."),
) -> None:
    """Vary each Wiedemann 99 parameter over the paper's range and report the minimum mean TTC and
    the minimum TTC of the altered cars per value."""
    from aveas_format.plot.sensitivity import plot_sensitivity
    from aveas_format.sim.scenario import W99_RANGES
    from aveas_format.sim.sensitivity import sensitivity

    check_output_dir(output, overwrite)
    sc = _scenario(config, None, duration)
    output.mkdir(parents=True, exist_ok=True)
    rows = sensitivity(sc, params=param or None, n_values=values, fraction=fraction,
                       workers=workers, scheduler=scheduler, progress=True,
                       min_ttc_samples=min_ttc_samples)
    from aveas_format.safeio import write_text_atomic

    write_text_atomic(output / "sensitivity.json", json.dumps(rows, indent=2))
    plot_sensitivity(rows, output / "sensitivity.png", W99_RANGES)
    for r in rows:
        if "error" in r:
            err.print(f"{r['param']}={r['value']:.3g}: failed: {r['error']}")
        else:
            out.print(f"{r['param']}={r['value']:<8.3g} min mean TTC {r['min_mean_ttc']:7.2f} s   "
                      f"min TTC {r['min_ttc']:7.2f} s")
    err.print(f"wrote {output / 'sensitivity.json'} and {output / 'sensitivity.png'}")
    if any("error" in r for r in rows):
        raise typer.Exit(1)
