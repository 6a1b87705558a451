"""``aveas-format demo``: write, read back, validate and summarise a sample recording."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors, out


@app.command()
@handle_errors
def demo(
    output: Path = typer.Option(Path("demo-output"), "--output", "-o",
                                help="Directory for the sample recording (replaced if it exists)."),
    vehicles: int = typer.Option(60, "--vehicles", min=1, max=100_000, help="Number of vehicles."),
    duration: float = typer.Option(30.0, "--duration", min=1.0, help="Seconds to simulate."),
) -> None:
    """Generate a sample aerial highway recording (map, uncertainty, occlusions, metadata), write it
    as a directory and as a ZIP, export it as OpenLABEL, OpenSCENARIO, MCAP (Foxglove) and an ASAM OSI
    trace, read it
    back, validate it and print its summary."""
    import aveas_format
    from aveas_format.sample import highway_scene
    from aveas_format.validate.render import render_text

    output.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rec = highway_scene(n_vehicles=vehicles, duration_s=duration)
    err.print(f"generated {rec.states.num_rows:,} states of {rec.participants.num_rows} vehicles "
              f"in {time.perf_counter() - t0:.2f} s")
    d = rec.write(output / "highway.aveas", overwrite=True)
    z = rec.write(output / "highway.aveas.zip", overwrite=True)
    err.print(f"wrote {d} and {z}")
    from aveas_format.converters import get_converter

    for name, fn in (("openlabel", "highway.openlabel.json"), ("openscenario", "highway.xosc"),
                     ("mcap", "highway.mcap"), ("osi", "highway.osi")):
        written = get_converter(name, "export")(rec, output / fn)
        err.print(f"exported {name}: {', '.join(str(p) for p in written)}")
    back = aveas_format.open(z)
    same = back.states.equals(aveas_format.open(d).states)
    err.print(f"read back the ZIP form: {back.states.num_rows:,} states; equal to the directory "
              f"form: {same}")
    report = aveas_format.validate(d)
    out.print(render_text(report), end="")
    from aveas_format.cli.info import info as info_cmd

    info_cmd(d, as_json=False)
    if report.exit_code("error") != 0 or not same:
        raise typer.Exit(1)
