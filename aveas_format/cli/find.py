"""``aveas-format find ARCHIVE --where "min_ttc < 1.5" --top 20``: the most critical situations
across an archive, each optionally cut out as a small recording and an OpenSCENARIO file;
``--events``: the worst derived events (conflicts and near misses) instead."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out, print_table
from aveas_format.cli.options import (
    OutputFormat,
    dataset_argument,
    discover_dataset,
    event_figures_option,
    format_option,
    overwrite_option,
    print_failure,
    scheduler_option,
    workers_option,
)


def _pm(v, sd, fmt=".2f") -> str:
    if v is None:
        return "-"
    return f"{v:{fmt}}" + (f" ± {sd:{fmt}}" if sd is not None else "")


@app.command()
@handle_errors
def find(
    dataset: list[str] = dataset_argument(),
    where: str = typer.Option(None, "--where", help='Condition on the measures, e.g. "min_ttc < '
                              '1.5 and max_drac > 3" (min_ttc, max_drac, min_psd, min_pet, tet, '
                              "tit, cpi, ttc_samples_below, near_misses, hard_braking); with "
                              "--events on collision_probability, value, duration, time_start."),
    by: str = typer.Option("min_ttc", "--by", help="Rank by this measure (ascending for "
                           "min_ttc, min_psd, min_pet; descending otherwise)."),
    events: bool = typer.Option(False, "--events", help="List the worst derived events "
                                "(conflicts and near misses: pair, time, kind, value ± std, "
                                "collision probability), most likely to collide first, instead "
                                "of the participants' situations."),
    top: int = typer.Option(20, "--top", min=1, help="List at most this many situations."),
    cut: Path = typer.Option(None, "--cut", help="Write each listed situation into this "
                             "directory as a small recording (the two participants around the "
                             "moment, map included) and an OpenSCENARIO file."),
    before: float = typer.Option(5.0, "--before", min=0, help="Seconds cut before the moment."),
    after: float = typer.Option(3.0, "--after", min=0, help="Seconds cut after the moment."),
    figures: Path = event_figures_option(),
    fmt: OutputFormat = format_option(),
    workers: int = workers_option(),
    scheduler: str = scheduler_option(),
    overwrite: bool = overwrite_option(help="Replace cut-out files that exist."),
) -> None:
    """List the most critical situations of an archive: per participant of every recording its
    minimum TTC (with the other participant and the time) and its other measures with their std,
    from each recording's derived/criticality_summary; with --events its derived conflicts and
    near misses (run `aveas-format derive` first). Exit 3 when a recording could not be read."""
    from aveas_format.dataset.find import (
        EVENT_MEASURES,
        MEASURES,
        critical_events,
        cut_out,
        parse_where,
        rank,
        rank_events,
        situations,
    )

    try:
        parse_where(where, EVENT_MEASURES if events else MEASURES)
        if by not in MEASURES:
            raise ValueError(f"--by: unknown measure {by!r}; known: {', '.join(MEASURES)}")
        if figures is not None and not events:
            raise ValueError("--figures draws events: pass --events")
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None
    for d, name in ((cut, "--cut"), (figures, "--figures")):
        if d is not None and d.exists() and not d.is_dir():
            raise fail(f"{name}: {d}: exists and is not a directory", EXIT_USAGE)
    paths = discover_dataset(dataset, "searching", workers, scheduler)
    if events:
        table, missing, failed = critical_events(paths, workers=workers or None,
                                                 scheduler=scheduler, progress=True,
                                                 on_result=print_failure)
        if missing:
            err.print(f"{len(missing)} recording(s) have no derived events (run aveas-format "
                      f"derive on them first), e.g. {missing[0]}")
        found = rank_events(table, where, top)
    else:
        table, missing, failed = situations(paths, workers=workers or None, scheduler=scheduler,
                                            progress=True, on_result=print_failure)
        if missing:
            err.print(f"{len(missing)} recording(s) have no derived/criticality_summary (run "
                      f"aveas-format derive on them first), e.g. {missing[0]}")
        found = rank(table, where, by, top)
    rows = found.to_pylist()
    cuts: list[list[str]] = []
    if cut is not None:
        from aveas_format.dataset.find import cut_name

        for r in rows:  # before writing any: nothing is replaced without --overwrite
            for suffix in (".aveas", ".xosc"):
                p = cut / f"{cut_name(r)}{suffix}"
                if p.exists() and not overwrite:
                    raise fail(f"{p}: exists; pass --overwrite to replace it", EXIT_USAGE)
        for r in rows:
            cuts.append([str(p) for p in cut_out(r, cut, before_s=before, after_s=after,
                                                 overwrite=overwrite)])
    drawn = _figures(rows, figures, overwrite) if figures is not None else []
    if fmt.value == "json":
        res = [{**r, **({"cut": cuts[k]} if cuts else {}),
                **({"figure": drawn[k]} if drawn else {})} for k, r in enumerate(rows)]
        print(json.dumps({"recordings": len(paths), ("events" if events else "situations"):
                          table.num_rows, "matching": len(rows), "where": where,
                          "by": None if events else by, "results": res,
                          ("without_events" if events else "without_summary"): missing,
                          "failures": [{"path": p, "error": e} for p, e in failed]},
                         indent=2, default=str))
    elif events:
        from aveas_format.derive.events import EXPLAIN, format_probability, format_value

        print_table([[r["recording_id"], str(r["event_id"]), r["kind"].replace("_", " "),
                      f"{r['participant_id']}, {r['other_id']}", str(r["relation"] or "-"),
                      f"{r['time_start']:.2f}-{r['time_end']:.2f}",
                      str(r["metric"] or "-").upper(),
                      format_value(r["metric"], r["value"], r["value_std"]),
                      "-" if r["duration"] is None else f"{r['duration']:.2f}",
                      format_probability(r["collision_probability"],
                                         r["collision_probability_std"])] for r in rows],
                    ["recording", "event", "kind", "pair", "relation", "time s", "metric",
                     "value ± std", "critical s", "P(collision)"],
                    title=f"{len(rows)} worst event(s)" + (f" where {where}" if where else "")
                    + " (most likely to collide first)", right=(1, 5, 7, 8, 9))
        for k in ("kind", "P(collision)"):
            out.print(f"  {k}: {EXPLAIN[k]}")
    else:
        print_table([[r["recording_id"], str(r["participant_id"]),
                      "-" if r["other_id"] is None else str(r["other_id"]),
                      "-" if r["time"] is None else f"{r['time']:.2f}",
                      _pm(r["min_ttc"], r["min_ttc_std"]), _pm(r["max_drac"], r["max_drac_std"]),
                      _pm(r["min_psd"], r["min_psd_std"]), _pm(r["tet"], r["tet_std"])]
                     for r in rows],
                    ["recording", "participant", "with", "time s", "min TTC s", "max DRAC m/s²",
                     "min PSD", "TET s"],
                    title=f"{len(rows)} most critical situation(s) by {by}"
                    + (f" where {where}" if where else "") + " (± 1 std)",
                    right=(1, 2, 3, 4, 5, 6, 7))
    for k, c in enumerate(cuts):
        err.print(f"cut {rows[k]['recording_id']} participant {rows[k]['participant_id']}: "
                  + ", ".join(c))
    for p in drawn:
        err.print(f"wrote {p}")
    raise typer.Exit(3 if failed else 0)


def _figures(rows: list[dict], directory: Path, overwrite: bool) -> list[str]:
    """A figure per event row into ``directory`` (RECORDING-event-ID.png); nothing is replaced
    without ``overwrite``."""
    from aveas_format.dataset.discovery import local_copy
    from aveas_format.io.reader import open_recording
    from aveas_format.plot.criticality import event_figure
    from aveas_format.safeio import save_figure_atomic

    targets = [directory / f"{r['recording_id']}-event-{r['event_id']}.png" for r in rows]
    for p in targets:
        if p.exists() and not overwrite:
            raise fail(f"{p}: exists; pass --overwrite to replace it", EXIT_USAGE)
    directory.mkdir(parents=True, exist_ok=True)
    done = []
    for r, target in zip(rows, targets):
        with local_copy(r["path"]) as local:
            rec = open_recording(local, tables=["participants", "states"],
                                 participants=[r["participant_id"], r["other_id"]], verify=False)
            ev = {**r, "participant_ids": [r["participant_id"], r["other_id"]],
                  "time_extreme": r["time"]}
            done.append(str(save_figure_atomic(event_figure(rec, ev), target, dpi=110)))
    return done
