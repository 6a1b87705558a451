"""``aveas-format plot REC -o DIR``: the figures of the validation report as PNG files."""

from __future__ import annotations

from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors


@app.command()
@handle_errors
def plot(
    recording: Path = typer.Argument(..., help="A recording: NAME.aveas directory or NAME.aveas.zip."),
    output: Path = typer.Option(Path("figures"), "--output", "-o", help="Directory for the PNG "
                                "files (created)."),
    findings: bool = typer.Option(True, "--findings/--no-findings", help="Validate first and mark "
                                  "the located findings on the map."),
) -> None:
    """Write the report figures as PNG: map.png (lanes, trajectories, findings), speed.png and
    acceleration.png (histograms per class), sample_rate.png (sample rate over time)."""
    import aveas_format
    from aveas_format.plot import save_figures

    rec = aveas_format.open(recording)
    found = aveas_format.validate(rec).findings() if findings else []
    for p in save_figures(rec, output, found):
        err.print(f"wrote {p}")
