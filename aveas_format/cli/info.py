"""``aveas-format info REC``: a summary of a recording."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from aveas_format.cli.app import app
from aveas_format.cli.common import handle_errors, out


@app.command()
@handle_errors
def info(
    recording: Path = typer.Argument(..., help="A recording: NAME.aveas directory or NAME.aveas.zip."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """Summarise a recording: participants per class, duration, rate, columns present, coverage."""
    import aveas_format

    rec = aveas_format.open(recording)
    s = rec.summary()
    if rec.derived or (rec.events is not None and rec.events.num_rows):
        from aveas_format.derive import criticality_summary

        s["criticality"] = criticality_summary(rec)
    if as_json:
        print(json.dumps(s, indent=2))
        return
    out.print(f"[bold]{s['recording_id']}[/]" + (f" — {s['title']}" if s.get("title") else ""))
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
        ("coverage", s["coverage"] or "not given"),
    ]
    if "criticality" in s:
        rows.append(("criticality", json.dumps(s["criticality"], default=str)))
    t = Table(show_header=False, show_edge=False, pad_edge=False, box=None)
    t.add_column(style="bold")
    t.add_column()
    for k, v in rows:
        t.add_row(k, str(v))
    out.print(t)
    cov = s.get("column_coverage") or {}
    if cov:
        ct = Table(title="states columns (share of non-null values)", show_edge=False)
        ct.add_column("column")
        ct.add_column("non-null", justify="right")
        for c, v in cov.items():
            ct.add_row(c, f"{100 * v:.1f} %")
        out.print(ct)
