"""``aveas-format fit``: fit behaviour-model parameters to recordings with SUMO."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out

fit_app = typer.Typer(help="Fit behaviour-model parameters to recordings (maximum likelihood "
                      "with SUMO; docs/fitting.md).", no_args_is_help=True)
app.add_typer(fit_app, name="fit")


def _range(text: str | None) -> tuple[float, float] | None:
    if not text:
        return None
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise fail(f"--s-range {text!r}: expected MIN,MAX", EXIT_USAGE) from None
    return a, b


@fit_app.command("desired-speed")
@handle_errors
def desired_speed(
    recordings: list[Path] = typer.Argument(..., help="Recordings with the observed vehicles."),
    output: Path = typer.Option(..., "--output", "-o", help="Output directory (runs.jsonl/.parquet, "
                                "best.json, figures); an existing one is resumed."),
    config: Path = typer.Option(None, "--config", "-c", help="Scenario TOML of the simulation "
                                "(default: the paper's autobahn)."),
    restarts: int = typer.Option(100, "--restarts", "-r", min=1, help="Nelder-Mead starts."),
    workers: int = typer.Option(1, "--workers", "-w", help="Local processes (0 = one per core)."),
    scheduler: str = typer.Option(None, "--scheduler", help="Dask scheduler address tcp://... "
                                  "(overrides --workers)."),
    maxfev: int = typer.Option(120, "--maxfev", help="Evaluations per restart at most."),
    seed: int = typer.Option(0, "--seed", help="Seed of the starting points."),
    bandwidth: str = typer.Option("silverman", "--bandwidth", help="KDE bandwidth: silverman, "
                                  "scott or a number (km/h)."),
    bounds: str = typer.Option(None, "--bounds", help="JSON {\"mu_car\": [lo, hi], ...} (km/h)."),
    road: str = typer.Option(None, "--road", help="Use only samples on this road id."),
    s_range: str = typer.Option(None, "--s-range", help="Use only samples with road_s in MIN,MAX."),
) -> None:
    """Fit the desired-speed distributions N(mu, sigma) of cars and trucks to the per-vehicle mean
    speeds of recordings (the paper's experiment)."""
    import numpy as np

    import aveas_format
    from aveas_format.fit import FitConfig, fit_desired_speed, recorded_mean_speeds
    from aveas_format.sim.scenario import Scenario

    classes = ("car", "truck")
    rec_speeds: dict[str, list] = {c: [] for c in classes}
    for p in recordings:
        v = recorded_mean_speeds(aveas_format.open(p), classes=classes, road_id=road,
                                 s_range=_range(s_range))
        for c in classes:
            rec_speeds[c].extend(v[c].tolist())
    used = [c for c in classes if rec_speeds[c]]
    if not used:
        raise fail("the recordings hold no cars or trucks", EXIT_USAGE)
    err.print("recorded: " + ", ".join(f"{len(rec_speeds[c])} {c}s" for c in used))
    cfg: dict = {"scenario": Scenario.from_toml(config) if config else Scenario(),
                 "classes": used, "restarts": restarts, "maxfev": maxfev, "seed": seed}
    try:
        cfg["bandwidth"] = float(bandwidth)
    except ValueError:
        cfg["bandwidth"] = bandwidth
    if bounds:
        try:
            cfg["bounds"] = {k: tuple(v) for k, v in json.loads(bounds).items()}
        except (json.JSONDecodeError, TypeError, AttributeError):
            raise fail(f"--bounds {bounds!r}: expected JSON like {{\"mu_car\": [100, 160]}}",
                       EXIT_USAGE) from None
    fc = FitConfig(**cfg)
    res = fit_desired_speed({c: np.asarray(rec_speeds[c]) for c in used}, fc, workers=workers,
                            scheduler=scheduler, outdir=output, progress=True)
    for f in res.failed:
        err.print(f"failed: {f}")
    if not res.runs:
        raise fail("every restart failed")
    b = res.best
    out.print(json.dumps({"best": {n: round(b[n], 3) for n in fc.names}, "neg_log_likelihood":
                          round(b["fun"], 4), "restarts": len(res.runs)}, indent=2))
    err.print(f"wrote {output}/runs.parquet, best.json, fit_histogram.png, fit_parameters.png")
