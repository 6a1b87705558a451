"""``aveas-format info REC``: a summary of a recording."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import handle_errors, out, print_table
from aveas_format.cli.options import (
    OutputFormat,
    event_figures_option,
    format_option,
    legacy_json_option,
    output_format,
)


def coverage_lonlat(rec: Any, wkt: str | None) -> list[float] | None:
    """``[lon_min, lat_min, lon_max, lat_max]`` (degrees) of the coverage polygon, through the
    recording's CRS and map offset (edges densified to 10 m); None without a coverage or a
    readable CRS."""
    if not wkt or not rec.meta.crs:
        return None
    import numpy as np
    import shapely

    from aveas_format.errors import AveasError
    from aveas_format.crs import LocalFrame

    try:
        xy = shapely.get_coordinates(shapely.segmentize(shapely.from_wkt(wkt), 10.0))
        lon, lat = LocalFrame.of(rec, warn=False).to_wgs84(xy[:, 0], xy[:, 1])
    except (AveasError, shapely.errors.ShapelyError, ValueError):
        return None
    if not len(lon) or not (np.isfinite(lon).all() and np.isfinite(lat).all()):
        return None
    return [round(float(v), 7) for v in (lon.min(), lat.min(), lon.max(), lat.max())]


def _coverage_text(s: dict[str, Any]) -> str:
    if not s["coverage"]:
        return "not given"
    import shapely

    try:
        area = f"{shapely.from_wkt(s['coverage']).area:,.0f} m²"
    except shapely.errors.ShapelyError:
        area = s["coverage"]
    b = s.get("coverage_lonlat_bounds")
    return area + (f", lon {b[0]:.6f} .. {b[2]:.6f}, lat {b[1]:.6f} .. {b[3]:.6f}" if b else "")


@app.command()
@handle_errors
def info(
    recording: Path = typer.Argument(..., help="A recording: NAME.aveas directory or NAME.aveas.zip."),
    fmt: OutputFormat = format_option(),
    as_json: bool = legacy_json_option(),
    figures: Path = event_figures_option(),
) -> None:
    """Summarise a recording: participants per class, duration, rate, columns present, coverage
    (also in lon/lat where the CRS is known) and, where it is derived, its criticality: the
    summary measures and the worst events (conflicts and near misses)."""
    import aveas_format

    rec = aveas_format.open(recording)
    s = rec.summary()
    s["coverage_lonlat_bounds"] = coverage_lonlat(rec, s["coverage"])
    if rec.derived or (rec.events is not None and rec.events.num_rows):
        from aveas_format.derive import criticality_summary

        s["criticality"] = criticality_summary(rec)
    written = _event_figures(rec, (s.get("criticality") or {}).get("worst") or [], figures)
    if output_format(fmt, as_json) == "json":
        if figures is not None:
            s["figures"] = [str(p) for p in written]
        print(json.dumps(s, indent=2, default=str))
        return
    from rich.markup import escape

    out.print(f"[bold]{escape(s['recording_id'])}[/]"
              + (f" — {escape(s['title'])}" if s.get("title") else ""), markup=True)
    rows = [
        ("path", s["path"]),
        ("format", s["format_version"] + (f" (migrated from {s['migrated_from']})"
                                          if s["migrated_from"] else "")),
        ("acquisition", f"{s['acquisition_method']} by {s['partner']}, provenance {s['provenance']}"),
        ("start", s["start_time"]),
        ("duration", f"{s['duration_s']:.2f} s"),
        ("rate", f"nominal {s['nominal_rate_hz']:g} Hz, observed {s.get('observed_rate_hz') or '-'} Hz"),
        ("location", f"lon {s['location']['lon']:.6f}, lat {s['location']['lat']:.6f}"),
        ("crs", s["crs"]),
        ("map", f"{s['map']['file']} (OpenDRIVE {s['map']['opendrive_version']})"),
        ("tables", ", ".join(f"{k} {v:,}" for k, v in s["tables"].items())),
        ("participants", ", ".join(f"{k} {v}" for k, v in s.get("participants_per_class", {}).items())
         or "none"),
        ("on map", f"{100 * s['on_map_share']:.1f} % of states" if s.get("on_map_share") is not None
         else "-"),
        ("coverage", _coverage_text(s)),
    ]
    print_table(rows)
    cov = s.get("column_coverage") or {}
    if cov:
        print()
        print_table([(c, f"{100 * v:.1f} %") for c, v in cov.items()], ("states column", "non-null"),
                    right=(1,))
    if "criticality" in s:
        print()
        _print_criticality(rec, s["criticality"])
    for p in written:
        out.print(f"wrote {p}")


def _event_figures(rec, worst: list[dict], directory: Path | None) -> list[Path]:
    """One figure per event of ``worst`` into ``directory`` (none without it)."""
    if directory is None or not worst:
        return []
    from aveas_format.plot.criticality import event_figure
    from aveas_format.safeio import save_figure_atomic

    directory.mkdir(parents=True, exist_ok=True)
    return [save_figure_atomic(event_figure(rec, r), directory / f"event-{r['event_id']}.png",
                               dpi=110) for r in worst]


def _pm(value, std, fmt: str = ".2f") -> str:
    """``1.23 ± 0.05`` (``-`` where there is no value)."""
    if value is None:
        return "-"
    return f"{value:{fmt}}" + (f" ± {std:{fmt}}" if std is not None else "")


def _print_criticality(rec, crit: dict) -> None:
    """The criticality of the recording (derived/criticality_summary, else the events' summary)
    and of its most critical participants: a small table; then its worst events."""
    from aveas_format.derive.events import EXPLAIN, format_probability, format_value
    from aveas_format.plot.criticality import cpi_text

    th = crit.get("thresholds") or {}
    cs = rec.derived.get("criticality_summary")
    counts = (f"{crit.get('conflicts', 0)} conflicts, {crit.get('near_misses', 0)} near misses, "
              f"{crit.get('hard_braking', 0)} hard braking")
    if cs is None or not cs.num_rows:
        m = crit.get("min_ttc_s") or {}
        out.print(f"criticality: min TTC {_pm(m.get('value'), m.get('std'))} s, {counts} "
                  "(derive criticality_summary for TET/TIT, CPI, DRAC, PSD)")
    else:
        rows = cs.to_pylist()
        whole = next((r for r in rows if str(r["scope"]) == "recording"), None)
        per = sorted((r for r in rows if str(r["scope"]) == "participant"
                      and r["min_ttc"] is not None), key=lambda r: r["min_ttc"])[:3]
        cols = ([whole] if whole else []) + per
        table: list[list[str]] = []

        def line(label, fn):
            table.append([label, *(fn(r) for r in cols)])

        line("min TTC (s)", lambda r: _pm(r["min_ttc"], r["min_ttc_std"]))
        line("  at (s), with", lambda r: "-" if r["min_ttc_time"] is None else
             f"{r['min_ttc_time']:.2f}, {r['min_ttc_other_id']}")
        line("samples below", lambda r: str(r["ttc_samples_below"]))
        line("TET (s)", lambda r: _pm(r["tet"], r["tet_std"]))
        line("TIT (s²)", lambda r: _pm(r["tit"], r["tit_std"]))
        line("max DRAC m/s²", lambda r: _pm(r["max_drac"], r["max_drac_std"]))
        line("min PSD", lambda r: _pm(r["min_psd"], r["min_psd_std"]))
        line("min PET (s)", lambda r: _pm(r["min_pet"], r["min_pet_std"]))
        line("CPI", lambda r: cpi_text(r["cpi"], r["cpi_std"]))
        line("conflicts", lambda r: str(r.get("conflicts") if r.get("conflicts") is not None
                                        else "-"))
        line("near misses", lambda r: str(r["near_misses"]))
        line("hard braking", lambda r: str(r["hard_braking"]))
        line("worst events", lambda r: ", ".join(map(str, (r["worst_events"] or [])[:3])) or "-")
        header = ["measure"] + ["recording" if r["participant_id"] is None
                                else f"participant {r['participant_id']}" for r in cols]
        print_table(table, header, title=f"criticality (TTC threshold {th.get('ttc_s', 1.5):g} "
                    "s; ± 1 std; the participants with the smallest TTC)",
                    right=tuple(range(1, len(header))))
        for k in ("TET / TIT", "CPI"):
            out.print(f"  {k}: {EXPLAIN[k]}")
    worst = crit.get("worst") or []
    print()
    if not worst:
        out.print(f"no conflicts and no near misses ({counts}): no pair's TTC, PET or DRAC was "
                  "beyond its threshold with the evidence the data's uncertainty gives")
        return
    rows_ = [[str(r["event_id"]), r["kind"].replace("_", " "),
              ", ".join(map(str, r["participant_ids"] or [])), str(r.get("relation") or "-"),
              f"{r['time_start']:.2f}-{r['time_end']:.2f}", str(r.get("metric") or "-").upper(),
              format_value(r.get("metric"), r.get("value"), r.get("value_std")),
              "-" if r.get("duration") is None else f"{r['duration']:.2f}",
              format_probability(r.get("collision_probability"),
                                 r.get("collision_probability_std"))] for r in worst]
    print_table(rows_, ["event", "kind", "pair", "relation", "time s", "metric", "value ± std",
                        "critical s", "P(collision)"],
                title=f"worst events ({counts}; most likely to collide first)",
                right=(0, 4, 6, 7, 8))
    for k in ("kind", "value", "P(collision)"):
        out.print(f"  {k}: {EXPLAIN[k]}")
