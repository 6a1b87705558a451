"""``aveas-format demo``: write, derive, read back, validate and summarise a sample recording, then
write its HTML validation report (with its criticality) and figures, a second recording with real
conflicts and its report, and say what to try next."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from aveas_format.cli.app import app
from aveas_format.cli.common import err, handle_errors, out
from aveas_format.cli.options import check_output_dir, overwrite_option

#: the sample road grows (x1.5 at least per try) until every vehicle drives on it, up to this
MAX_ROAD_M = 50_000.0


def sample_scene(vehicles: int, duration: float):
    """The sample highway scene with every one of ``vehicles`` on the road: the traffic starts
    upstream at safe headways, so a short road in a short time sees only the first ones; the
    road is lengthened until all are seen (or :data:`MAX_ROAD_M`). Returns ``(rec, road length)``."""
    from aveas_format.sample import highway_scene

    length = 1000.0
    while True:
        rec = highway_scene(n_vehicles=vehicles, duration_s=duration, length_m=length)
        seen = rec.participants.num_rows
        if seen >= vehicles or length >= MAX_ROAD_M:
            return rec, length
        length = min(MAX_ROAD_M, round(length * max(1.5, 1.1 * vehicles / max(seen, 1)), -2))


@app.command()
@handle_errors
def demo(
    output: Path = typer.Option(Path("demo-output"), "--output", "-o",
                                help="Directory for the sample recording, its exports, report and "
                                "figures."),
    vehicles: int = typer.Option(60, "--vehicles", min=1, max=100_000, help="Number of vehicles "
                                 "(the road is lengthened until all of them drive on it)."),
    duration: float = typer.Option(30.0, "--duration", min=1.0, help="Seconds to simulate."),
    overwrite: bool = overwrite_option(help="Replace the files of an existing OUTPUT directory."),
) -> None:
    """Generate a sample aerial highway recording (map, uncertainty, occlusions, metadata), derive
    its kinematics and criticality, write it as a directory and as a ZIP, export it as OpenLABEL,
    OpenSCENARIO, MCAP (Foxglove) and an ASAM OSI trace, read it back, validate it, print its
    summary and write the HTML validation report and the figures next to it; then a minute of
    lane-keeping traffic with a planted cut-in and hard braking, derived, with its report."""
    import aveas_format
    from aveas_format.converters import get_converter
    from aveas_format.errors import MissingDependencyError
    from aveas_format.validate.render import render_text

    check_output_dir(output, overwrite)
    output.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rec, length = sample_scene(vehicles, duration)
    n = rec.participants.num_rows
    err.print(f"generated {rec.states.num_rows:,} states of {n} vehicles in "
              f"{time.perf_counter() - t0:.2f} s")
    if n < vehicles:
        err.print(f"note: {vehicles - n} of {vehicles} vehicles do not reach the {length / 1000:g} km "
                  f"road within {duration:g} s (the traffic starts upstream at safe headways); "
                  "a longer --duration lets them in")
    elif length > 1000.0:
        err.print(f"note: the road is {length / 1000:g} km long so that all {vehicles} vehicles "
                  f"drive on it within {duration:g} s")
    from aveas_format.derive import derive

    t0 = time.perf_counter()
    derive(rec)
    err.print(f"derived {', '.join(sorted(rec.derived))} and the events in "
              f"{time.perf_counter() - t0:.1f} s")
    d = rec.write(output / "highway.aveas", overwrite=True)
    z = rec.write(output / "highway.aveas.zip", overwrite=True)
    err.print(f"wrote {d} and {z}")
    for name, fn in (("openlabel", "highway.openlabel.json"), ("openscenario", "highway.xosc"),
                     ("mcap", "highway.mcap"), ("osi", "highway.osi")):
        try:
            written = get_converter(name, "export")(rec, output / fn)
        except MissingDependencyError as e:
            err.print(f"skipped the {name} export: {e}")
            continue
        err.print(f"exported {name}: {', '.join(str(p) for p in written)}")
    back = aveas_format.open(z)
    same = back.states.equals(aveas_format.open(d).states)
    err.print(f"read back the ZIP form: {back.states.num_rows:,} states; equal to the directory "
              f"form: {same}")
    report = aveas_format.validate(d)
    out.print(render_text(report), end="")
    from aveas_format.cli.info import info as info_cmd
    from aveas_format.cli.options import OutputFormat

    info_cmd(d, fmt=OutputFormat.text, as_json=False)
    look = _report_and_figures(d, report, output)
    look += _conflicts(output)
    print()
    print("Look at " + (" and ".join(str(p) for p in look) if look else f"{d}") + ". Next:")
    print(f"  aveas-format info {output / 'conflicts.aveas'} --figures {output / 'events'}"
          "   # its conflicts with a figure each")
    print(f"  aveas-format derive {d} -o {output / 'derived.aveas'} --ttc 5   # again, another "
          "TTC threshold")
    print("  aveas-format convert --list   # converters for your own data")
    if report.exit_code("error") != 0 or not same:
        raise typer.Exit(1)


def _conflicts(output: Path) -> list[Path]:
    """A minute of lane-keeping traffic with a planted cut-in and hard braking (aerial noise),
    derived, written as ``conflicts.aveas`` with its HTML report (its criticality section lists
    the conflicts with a figure each); what was written."""
    import aveas_format
    from aveas_format.derive import derive
    from aveas_format.errors import MissingDependencyError
    from aveas_format.plot import render_html
    from aveas_format.plot.recording import open_for_figures
    from aveas_format.safeio import write_text_atomic
    from aveas_format.sample.scenes import traffic_scene

    t0 = time.perf_counter()
    rec = traffic_scene(60.0, conflicts=(("cut_in", 1.0), ("hard_braking", 1.3)), seed=2)
    derive(rec)
    p = rec.write(output / "conflicts.aveas", overwrite=True)
    kinds = rec.events.column("kind").to_pylist() if rec.events is not None else []
    err.print(f"wrote {p}: a minute of traffic with a planted cut-in and hard braking, "
              f"{kinds.count('conflict')} conflicts and {kinds.count('near_miss')} near misses "
              f"found ({time.perf_counter() - t0:.1f} s)")
    report = aveas_format.validate(p)
    try:
        html = write_text_atomic(output / "conflicts-report.html",
                                 render_html(report, open_for_figures(p, report)))
    except MissingDependencyError as e:
        err.print(f"skipped the report of {p}: {e}")
        return [p]
    err.print(f"wrote {html}")
    return [html]


def _report_and_figures(path: Path, report, output: Path) -> list[Path]:
    """The HTML validation report and the figures of the recording at ``path``, next to it; what
    was written (without the [plot] extra the report has no figures and no figures are drawn,
    with a note)."""
    from aveas_format.errors import MissingDependencyError
    from aveas_format.plot import render_html, save_figures
    from aveas_format.plot.recording import open_for_figures
    from aveas_format.safeio import write_text_atomic

    rec = open_for_figures(path, report)
    html = write_text_atomic(output / "report.html", render_html(report, rec))
    try:
        figs = save_figures(rec, output / "figures", report.findings())
    except MissingDependencyError as e:
        err.print(f"wrote {html}; skipped the figures: {e}")
        return [html]
    err.print(f"wrote {html} and {len(figs)} figures in {output / 'figures'}")
    return [html, output / "figures"]
