"""``aveas-format find ARCHIVE --where "min_ttc < 1.5" --top 20``: the most critical situations
across an archive, each optionally cut out as a small recording and an OpenSCENARIO file."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_USAGE, err, fail, handle_errors, out
from aveas_format.cli.options import (
    OutputFormat,
    dataset_argument,
    discover_dataset,
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
                              "tit, cpi, ttc_samples_below, near_misses, hard_braking)."),
    by: str = typer.Option("min_ttc", "--by", help="Rank by this measure (ascending for "
                           "min_ttc, min_psd, min_pet; descending otherwise)."),
    top: int = typer.Option(20, "--top", min=1, help="List at most this many situations."),
    cut: Path = typer.Option(None, "--cut", help="Write each listed situation into this "
                             "directory as a small recording (the two participants around the "
                             "moment, map included) and an OpenSCENARIO file."),
    before: float = typer.Option(5.0, "--before", min=0, help="Seconds cut before the moment."),
    after: float = typer.Option(3.0, "--after", min=0, help="Seconds cut after the moment."),
    fmt: OutputFormat = format_option(),
    workers: int = workers_option(),
    scheduler: str = scheduler_option(),
    overwrite: bool = overwrite_option(help="Replace cut-out files that exist."),
) -> None:
    """List the most critical situations of an archive: per participant of every recording its
    minimum TTC (with the other participant and the time) and its other measures with their std,
    from each recording's derived/criticality_summary (run `aveas-format derive` first). Exit 3
    when a recording could not be read."""
    from aveas_format.dataset.find import MEASURES, cut_out, parse_where, rank, situations

    try:
        parse_where(where)
        if by not in MEASURES:
            raise ValueError(f"--by: unknown measure {by!r}; known: {', '.join(MEASURES)}")
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None
    if cut is not None and cut.exists() and not cut.is_dir():
        raise fail(f"{cut}: exists and is not a directory", EXIT_USAGE)
    paths = discover_dataset(dataset, "searching", workers, scheduler)
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
    if fmt.value == "json":
        res = [{**r, **({"cut": cuts[k]} if cuts else {})} for k, r in enumerate(rows)]
        print(json.dumps({"recordings": len(paths), "situations": table.num_rows,
                          "matching": len(rows), "where": where, "by": by, "results": res,
                          "without_summary": missing,
                          "failures": [{"path": p, "error": e} for p, e in failed]},
                         indent=2, default=str))
    else:
        t = Table(title=f"{len(rows)} most critical situation(s) by {by}"
                  + (f" where {where}" if where else "") + " (± 1 std)", show_edge=False,
                  title_justify="left")
        for c in ("recording", "participant", "with", "time s", "min TTC s", "max DRAC m/s²",
                  "min PSD", "TET s"):
            t.add_column(c, justify="left" if c == "recording" else "right")
        for r in rows:
            t.add_row(r["recording_id"], str(r["participant_id"]),
                      "-" if r["other_id"] is None else str(r["other_id"]),
                      "-" if r["time"] is None else f"{r['time']:.2f}",
                      _pm(r["min_ttc"], r["min_ttc_std"]), _pm(r["max_drac"], r["max_drac_std"]),
                      _pm(r["min_psd"], r["min_psd_std"]), _pm(r["tet"], r["tet_std"]))
        out.print(t)
        for k, c in enumerate(cuts):
            err.print(f"cut {rows[k]['recording_id']} participant {rows[k]['participant_id']}: "
                      + ", ".join(c))
    raise typer.Exit(3 if failed else 0)
