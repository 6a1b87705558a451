"""``aveas-format plot REC -o DIR``: the figures of the validation report as PNG files."""

from __future__ import annotations

from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors
from aveas_format.cli.options import check_output_dir, overwrite_option


@app.command()
@handle_errors
def plot(
    recording: Path = typer.Argument(..., help="A recording: NAME.aveas directory or NAME.aveas.zip."),
    output: Path = typer.Option(Path("figures"), "--output", "-o", help="Directory for the PNG "
                                "files (created)."),
    findings: bool = typer.Option(True, "--findings/--no-findings", help="Validate first and mark "
                                  "the located findings on the map."),
    overwrite: bool = overwrite_option(help="Replace the files of an existing OUTPUT directory."),
) -> None:
    """Write the report figures as PNG: map.png (lanes, trajectories, findings), speed.png and
    acceleration.png (histograms per class), sample_rate.png (sample rate over time)."""
    import aveas_format
    from aveas_format.errors import require
    from aveas_format.plot import save_figures

    require("matplotlib", extra="plot", what="figures")  # says so before any work

    check_output_dir(output, overwrite)
    from aveas_format.plot.recording import open_for_figures

    report = aveas_format.validate(recording) if findings else None
    rec = open_for_figures(recording, report)  # bounded: a subset of a large recording
    if getattr(rec, "figure_note", None):
        err.print(f"figures {rec.figure_note}")
    for p in save_figures(rec, output, report.findings() if report is not None else []):
        err.print(f"wrote {p}")
