"""``aveas-format derive REC``: compute derived tables (kinematics, interactions, encroachments,
traffic) and derived events, and write the recording."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NoReturn

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors
from aveas_format.errors import did_you_mean
from aveas_format.cli.options import (
    check_output,
    discover_dataset,
    overwrite_option,
    print_failure,
    recordings_argument,
    run_summary,
    scheduler_option,
    single_recording,
    workers_option,
)


def _parse_params(items: list[str]) -> dict[str, dict]:
    """``NAME.PARAM=VALUE`` (VALUE as JSON where it parses, else text) -> {NAME: {PARAM: VALUE}}."""
    out: dict[str, dict] = {}
    for it in items:
        key, sep, value = it.partition("=")
        name, dot, param = key.partition(".")
        if not sep or not dot or not name or not param:
            raise fail(f"--param {it!r}: expected NAME.PARAM=VALUE (e.g. kinematics.jerk_density=2)",
                       EXIT_USAGE)
        try:
            v = json.loads(value)
        except json.JSONDecodeError:
            v = value
        out.setdefault(name, {})[param] = v
    return out


@app.command()
@handle_errors
def derive(
    recordings: list[str] = recordings_argument(urls="URLs (then --output is a directory)"),
    only: list[str] = typer.Option(None, "--only", help="Run only this derivation (repeatable): "
                                   "kinematics, interactions, encroachments, traffic, events, "
                                   "criticality_summary. "
                                   "Missing prerequisites run too."),
    output: Path | None = typer.Option(None, "--output", "-o", help="Write the result here."),
    in_place: bool = typer.Option(False, "--in-place", help="Replace the input recording "
                                  "(atomically)."),
    overwrite: bool = overwrite_option(help="Replace OUTPUT (and the --report file) if it exists."),
    ttc: float | None = typer.Option(None, "--ttc", help="TTC threshold (s) for near-miss "
                                     "events (default: recording.json thresholds.ttc_s, else 1.5)."),
    pet: float | None = typer.Option(None, "--pet", help="PET threshold (s) for near-miss "
                                     "events (default: recording.json thresholds.pet_s, else 1.5)."),
    hard_braking: float | None = typer.Option(None, "--hard-braking", help="a_lon threshold "
                                              "(m/s², negative) for hard-braking events."),
    drac: float | None = typer.Option(None, "--drac", help="DRAC threshold (m/s²) for near-miss "
                                      "events (default: none, DRAC makes no events of its own)."),
    param: list[str] = typer.Option(None, "--param", help="A derivation parameter as "
                                    "NAME.PARAM=VALUE (repeatable; VALUE in JSON), e.g. "
                                    "traffic.cell_duration_s=30."),
    window: float | None = typer.Option(None, "--window", min=1.0, help="Derive by time "
                                        "windows of SECONDS with bounded memory (kinematics, "
                                        "interactions, conflicts, events, criticality_summary; "
                                        "60 is a good choice; docs/derive.md 'Large "
                                        "recordings'). One "
                                        "recording; --workers processes."),
    workers: int = workers_option(scope="Dataset or --window"),
    scheduler: str = scheduler_option(scope="Dataset"),
    report: Path = typer.Option(None, "--report", help="Dataset: also write the dataset report "
                                "to FILE (.json or .html)."),
) -> None:
    """Compute derived tables and events (FORMAT.md 10) and write the recording: to `--output`,
    or over the input with `--in-place`. Prints what was derived as JSON. `--window SECONDS`
    derives the criticality tables of a recording too large for memory by time windows, the same
    tables as at once (docs/derive.md "Large recordings")."""
    import aveas_format
    from aveas_format.derive import derive as run_derive
    from aveas_format.derive.registry import derivations

    recording = single_recording(recordings)  # None: a dataset
    if output is None and not in_place:
        raise fail("give --output PATH or --in-place", EXIT_USAGE)
    if output is not None and in_place:
        raise fail("give either --output or --in-place, not both", EXIT_USAGE)
    if recording is not None and output is not None:
        check_output(output, overwrite)
    if report is not None:
        check_output(report, overwrite)
    known = derivations()
    for name in only or []:
        if name not in known:
            raise fail(f"--only {name!r}: unknown derivation{did_you_mean(name, known)}; known: "
                       f"{', '.join(known)}", EXIT_USAGE)
    params: dict = _parse_params(param or [])
    for name in params:
        if name not in known:
            raise fail(f"--param {name}.*: unknown derivation{did_you_mean(name, known)}; known: "
                       f"{', '.join(known)}", EXIT_USAGE)
    ev = params.setdefault("events", {})
    if ttc is not None:
        ev["ttc_s"] = ttc
    if pet is not None:
        ev["pet_s"] = pet
    if hard_braking is not None:
        ev["hard_braking_mps2"] = hard_braking
    if drac is not None:
        ev["drac_mps2"] = drac
    if window is not None:
        if recording is None:
            raise fail("--window derives one recording (a dataset: derive its recordings one by "
                       "one)", EXIT_USAGE)
        _derive_windows(recording, output, in_place, overwrite, list(only) if only else None,
                        params, window, workers)
    elif recording is not None:
        _hint_window(recording)
    if recording is None:
        _derive_dataset(recordings, output, in_place, overwrite, list(only) if only else None,
                        params, workers, scheduler, report)
    target = recording if in_place else output
    assert target is not None  # --output or --in-place, checked above
    rec = aveas_format.open(recording)
    ran = run_derive(rec, only=list(only) if only else None, **params)
    path = rec.write(target, overwrite=in_place or overwrite)
    summary = {"recording": str(path), "derived": ran,
               "tables": {f"derived/{n}": t.num_rows for n, t in rec.derived.items()},
               "events": rec.events.num_rows if rec.events is not None else 0}
    print(json.dumps(summary, indent=2))
    err.print(f"derived {', '.join(ran)} -> {path}")


#: states rows above which deriving at once is likely to need several GB (about 1 kB per state
#: for all the derived tables and their std): derive prints a hint to use --window
LARGE_STATES = 3_000_000


def _hint_window(recording: str) -> None:
    from aveas_format.io.reader import open_recording

    try:
        entry = open_recording(recording, tables=["participants"], verify=False).meta.tables.get(
            "states")
    except Exception:  # noqa: BLE001 — only a hint; opening it for real reports the error
        return
    if entry is not None and entry.rows > LARGE_STATES:
        err.print(f"{recording}: {entry.rows:,} states; for bounded memory derive by time "
                  "windows: --window 60 (docs/derive.md 'Large recordings')")


def _derive_windows(recording: str, output: Path | None, in_place: bool, overwrite: bool,
                    only: list[str] | None, params: dict, window: float, workers: int) -> NoReturn:
    """``--window``: the criticality tables by time windows
    (:func:`aveas_format.derive.streamed.write_by_windows`), written to OUTPUT or in place."""
    from aveas_format.derive.streamed import WINDOW_TABLES, write_by_windows

    outside = [n for n in only or [] if n not in WINDOW_TABLES]
    if outside:
        raise fail(f"--window derives {', '.join(WINDOW_TABLES)}; --only {outside[0]} is not "
                   "derived by windows (derive it without --window)", EXIT_USAGE)
    if "pet_s" in params.get("events", {}):
        raise fail("--pet (events.pet_s): PET events need encroachments, which are not derived "
                   "by windows (derive them without --window)", EXIT_USAGE)
    flat: dict = {}
    for name, ps in params.items():
        if name not in WINDOW_TABLES:
            raise fail(f"--param {name}.*: {name} is not derived by windows ("
                       f"{', '.join(WINDOW_TABLES)})", EXIT_USAGE)
        for k, v in ps.items():
            if flat.get(k, v) != v:
                raise fail(f"--param {name}.{k}: differs from another derivation's {k}; by "
                           "windows a parameter has one value for all", EXIT_USAGE)
            flat[k] = v
    target = Path(recording) if in_place else output
    assert target is not None  # --output or --in-place, checked by the caller
    info = write_by_windows(recording, target, window_s=window, workers=workers or None,
                            overwrite=in_place or overwrite, progress=True, **flat)
    summary = {"recording": info["recording"], "derived": info["derived"],
               "tables": info["tables"], "events": info["tables"]["events"],
               "windows": info["windows"],
               "window_s": window, "worker_peak_mb": round(info["worker_peak_kb"] / 1024, 1)}
    print(json.dumps(summary, indent=2))
    err.print(f"derived {', '.join(info['derived'])} in {info['windows']} windows of {window:g} s "
              f"-> {info['recording']}")
    raise typer.Exit(0)


def _derive_dataset(specs: list[str], output: Path | None, in_place: bool, overwrite: bool,
                    only: list[str] | None, params: dict, workers: int, scheduler: str | None,
                    report: Path | None) -> NoReturn:
    """Derive every recording of a dataset, one task each, into the directory OUTPUT (same
    relative layout) or in place; exit 3 when any recording failed."""
    from aveas_format.dataset import derive_dataset, is_recording
    from aveas_format.safeio import write_text_atomic

    if output is not None and output.exists() and (not output.is_dir() or is_recording(output)):
        raise fail(f"{output}: for a dataset, --output is a directory (of recordings)",
                   EXIT_USAGE)
    paths = discover_dataset(specs, "deriving", workers, scheduler)
    rep = derive_dataset(paths, output_dir=output, in_place=in_place, overwrite=overwrite,
                         only=only, params=params, workers=workers or None, scheduler=scheduler,
                         progress=True, specs=list(specs), on_result=print_failure)
    d = rep.to_dict()
    summary = run_summary(d, ("path", "recording_id", "output", "derived", "tables", "events",
                              "min_ttc_s", "min_pet_s", "near_misses", "hard_braking"),
                          exit_code=True)
    print(json.dumps(summary, indent=2))
    if report is not None:
        write_text_atomic(report, rep.to_html() if report.suffix.lower() in (".html", ".htm")
                          else rep.to_json())
    err.print(f"derived {d['completed']} of {d['recordings']} recordings"
              + (f", {d['failed']} failed" if d["failed"] else "")
              + (f" -> {output}" if output else " in place"))
    raise typer.Exit(rep.exit_code())
