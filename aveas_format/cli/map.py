"""``aveas-format map``: OpenDRIVE maps — info, project (world -> road), plot, check, convert
(Lanelet2 -> OpenDRIVE), build (from trajectories)."""

from __future__ import annotations

import csv
import json
import sys
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import typer
from aveas_format.cli.app import app
from aveas_format.cli.common import EXIT_FINDINGS, EXIT_USAGE, err, fail, handle_errors, print_table
from aveas_format.cli.options import (
    OutputFormat,
    check_output,
    format_option,
    legacy_json_option,
    output_format,
    overwrite_option,
)

map_app = typer.Typer(
    help="OpenDRIVE maps: `info` (summary), `project` (x, y -> road, lane, s, t), `plot` (PNG of "
    "the lanes), `check` (self-consistency), `convert` (a Lanelet2 map to OpenDRIVE) and `build` "
    "(a map from recorded trajectories).",
    no_args_is_help=True,
    rich_markup_mode="markdown",
    context_settings={"help_option_names": ["-h", "--help"]},
)
app.add_typer(map_app, name="map")

_MAP_HELP = "The OpenDRIVE map (.xodr), or a recording (directory or .aveas.zip): its map."


def _load(path: Path | None):
    """The map of ``path``: an OpenDRIVE file, or the map a recording (its directory or
    .aveas.zip) carries."""
    if path is None:
        raise fail("Missing argument 'MAP'.", EXIT_USAGE)
    from aveas_format.opendrive import load_map

    if path.is_dir() or path.name.lower().endswith(".zip"):
        from aveas_format.errors import RecordingIOError
        from aveas_format.io.reader import open_recording

        if path.is_dir() and not (path / "recording.json").exists():
            raise RecordingIOError("a directory, but neither an OpenDRIVE map nor a recording (no "
                                   "recording.json)", path=path)
        rec = open_recording(path, tables=["participants"])
        if rec.map_source is None:
            raise RecordingIOError("the recording has no map", path=path)
        net = rec.map
        net.path = f"{path}/{rec.meta.map.file}"
        return net
    return load_map(path)


# ----------------------------------------------------------------------------------------------
# info
def map_summary(net) -> dict[str, Any]:
    """The summary printed by ``map info`` (also its ``--json``)."""
    from aveas_format.errors import FormatError
    from aveas_format.crs import parse_crs

    roads = list(net.roads.values())
    lane_types: Counter[str] = Counter()
    lane_len: Counter[str] = Counter()
    n_sections = 0
    for r in roads:
        starts = [sec.s for sec in r.lane_sections] + [r.length]
        for i, sec in enumerate(r.lane_sections):
            n_sections += 1
            seclen = max(0.0, min(starts[i + 1], r.length) - sec.s)
            for ln in sec.left + sec.right:
                lane_types[ln.type] += 1
                lane_len[ln.type] += seclen
    geo = net.header.geo_reference
    crs: dict[str, Any] = {"geo_reference": geo, "offset": list(net.header.offset) if net.header.offset else None}
    if geo:
        try:
            parsed = parse_crs(geo)
            c = parsed.crs
            name = c.name
            if name == "unknown":
                op = c.coordinate_operation
                name = f"{c.type_name}: {op.method_name}" if op is not None else c.type_name
            crs.update(read_as=name, proj=c.srs, lenient=parsed.lenient,
                       notes=list(parsed.notes), error=None)
        except FormatError as e:
            crs.update(read_as=None, proj=None, lenient=False, notes=[], error=e.message)
    else:
        crs.update(read_as=None, proj=None, lenient=False, notes=["no <geoReference>: local coordinates only"],
                   error=None)
    kinds = Counter(g.kind for r in roads for g in r.geometries)
    jtypes = Counter(j.type for j in net.junctions.values())
    b = net.bounds if roads else (0.0, 0.0, 0.0, 0.0)
    return {
        "path": net.path,
        "opendrive_version": net.header.version,
        "name": net.header.name,
        "vendor": net.header.vendor,
        "date": net.header.date,
        "roads": len(roads),
        "junction_roads": sum(r.junction is not None for r in roads),
        "junctions": len(net.junctions),
        "junction_types": dict(sorted(jtypes.items())),
        "lane_sections": n_sections,
        "lanes": sum(lane_types.values()),
        "lane_types": dict(lane_types.most_common()),
        "lane_length_m": {k: round(v, 3) for k, v in lane_len.most_common()},
        "length_m": round(sum(r.length for r in roads), 3),
        "length_outside_junctions_m": round(sum(r.length for r in roads if r.junction is None), 3),
        "geometry_types": dict(kinds.most_common()),
        "objects": sum(len(r.objects) for r in roads),
        "signals": sum(len(r.signals) for r in roads),
        "bounds": [round(float(v), 3) for v in b],
        "crs": crs,
    }


@map_app.command("info")
@handle_errors
def info(
    map_file: Path = typer.Argument(None, metavar="MAP", help=_MAP_HELP),
    fmt: OutputFormat = format_option(),
    as_json: bool = legacy_json_option(),
) -> None:
    """Summarise a map: roads, junctions, lanes by type, length, geometry types, CRS and how the
    `<geoReference>` was read."""
    fmt_ = output_format(fmt, as_json)
    s = map_summary(_load(map_file))
    if fmt_ == "json":
        print(json.dumps(s, indent=2))
        return
    c = s["crs"]
    if c["geo_reference"] is None:
        crs_txt = "none (local coordinates)"
    elif c["error"]:
        crs_txt = f"{c['geo_reference']!r}: UNREADABLE ({c['error']})"
    else:
        crs_txt = f"{c['geo_reference']!r} -> {c['read_as']}"
        if c["lenient"]:
            crs_txt += f" [lenient: {'; '.join(c['notes'])}]"
    rows = [
        ("map", f"{s['path'] or '-'} (OpenDRIVE {s['opendrive_version']}"
         + (f", {s['name']}" if s["name"] else "") + (f", by {s['vendor']}" if s["vendor"] else "") + ")"),
        ("roads", f"{s['roads']} ({s['junction_roads']} in junctions)"),
        ("junctions", f"{s['junctions']}" + (" (" + ", ".join(f"{k} {v}" for k, v in
                                                               s["junction_types"].items()) + ")"
                                              if s["junction_types"] else "")),
        ("length", f"{s['length_m']:,.1f} m ({s['length_outside_junctions_m']:,.1f} m outside junctions)"),
        ("lanes", f"{s['lanes']} in {s['lane_sections']} lane sections: "
         + ", ".join(f"{k} {v}" for k, v in s["lane_types"].items())),
        ("lane length", ", ".join(f"{k} {v / 1000:,.2f} km" for k, v in s["lane_length_m"].items()) or "-"),
        ("geometry", ", ".join(f"{k} {v}" for k, v in s["geometry_types"].items())),
        ("objects", f"{s['objects']} objects, {s['signals']} signals"),
        ("bounds", "x {0:,.1f} .. {2:,.1f}, y {1:,.1f} .. {3:,.1f} m".format(*s["bounds"])),
        ("crs", crs_txt),
        ("offset", "x {:.3f}, y {:.3f}, z {:.3f}, hdg {:.6f}".format(*c["offset"]) if c["offset"] else "none"),
    ]
    print_table(rows)


# ----------------------------------------------------------------------------------------------
# project
def _csv_problem(path: Path, columns: list[str]) -> str | None:
    """The first malformed line of a CSV file (wrong field count, non-numeric x/y/heading), as a
    message naming line and column; None when the file looks fine."""
    numeric = [c for c in ("x", "y", "heading") if c in columns]
    with path.open(newline="", encoding="utf-8", errors="replace") as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            return "the file is empty"
        idx = {c: header.index(c) for c in numeric if c in header}
        for row in reader:
            if not row:
                continue
            if len(row) != len(header):
                return f"line {reader.line_num}: {len(row)} fields, the header has {len(header)}"
            for c, i in idx.items():
                v = row[i].strip()
                if v == "":
                    return f"line {reader.line_num}, column {c}: empty value"
                try:
                    float(v)
                except ValueError:
                    return f"line {reader.line_num}, column {c}: {v!r} is not a number"
    return None


def read_points(path: Path):
    """The points table (pyarrow) of a CSV or Parquet file with columns x, y[, heading]."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from aveas_format.errors import FormatError, RecordingIOError

    if not path.exists():
        raise RecordingIOError("no such file", path=path)
    if path.is_dir():
        raise RecordingIOError("is a directory, not a CSV or Parquet file", path=path)
    if path.suffix.lower() in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        try:
            table = pq.read_table(path)
        except (pa.ArrowException, OSError) as e:
            raise FormatError(f"cannot read Parquet: {e}", path=path) from None
        bad_line = None
    else:
        import pyarrow.csv as pcsv

        try:
            table = pcsv.read_csv(path)
        except (pa.ArrowException, OSError) as e:
            where = _csv_problem(path, ["x", "y", "heading"])
            raise FormatError(where or f"cannot read CSV: {str(e).splitlines()[0]}", path=path) from None
        bad_line = True
    cols = table.column_names
    missing = [c for c in ("x", "y") if c not in cols]
    if missing:
        raise FormatError(f"no column {' or '.join(repr(c) for c in missing)} (columns: {', '.join(cols) or 'none'})",
                          path=path)
    if table.num_rows == 0:
        raise FormatError("no points in the file (its header has no rows after it)", path=path)
    for c in ("x", "y", "heading"):
        if c not in cols:
            continue
        col = table.column(c)
        if not (pa.types.is_floating(col.type) or pa.types.is_integer(col.type)) or col.null_count:
            if bad_line:
                where = _csv_problem(path, cols)
                if where:
                    raise FormatError(where, path=path)
            if col.null_count:
                row = int(pc.index(pc.is_null(col), True).as_py())
                raise FormatError(f"row {row}, column {c}: empty value", path=path)
            raise FormatError(f"column {c}: type {col.type}, not a number", path=path)
    return table


def write_table(table, path: Path | None) -> None:
    """CSV (or Parquet by the suffix) to ``path`` (atomically); CSV to stdout when None."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    if path is None:
        pcsv.write_csv(table, sys.stdout.buffer)
        sys.stdout.flush()
        return
    from aveas_format.safeio import write_bytes_atomic, write_parquet_atomic

    if path.suffix.lower() in (".parquet", ".pq"):
        write_parquet_atomic(table, path)
    else:
        buf = pa.BufferOutputStream()
        pcsv.write_csv(table, buf)
        write_bytes_atomic(path, buf.getvalue().to_pybytes())


@map_app.command("project")
@handle_errors
def project(
    map_file: Path = typer.Argument(None, metavar="MAP", help=_MAP_HELP),
    points: Path = typer.Option(None, "--points", "-p", help="CSV or Parquet (.parquet) with columns x, y "
                                "[, heading] in the map's local frame (other columns are kept)."),
    output: Path = typer.Option(None, "--output", "-o", help="Output .csv or .parquet (default: CSV "
                                "on stdout)."),
    overwrite: bool = overwrite_option(),
    drivable_only: bool = typer.Option(False, "--drivable-only", help="Ignore non-drivable lanes "
                                       "(sidewalks, shoulders, ...)."),
    track: bool = typer.Option(False, "--track", help="Choose among overlapping roads by continuity "
                               "along trajectories (columns track_id and time when present, else "
                               "the row order)."),
) -> None:
    """World -> road coordinates: append road_id, lane_id, s, t, lane_offset, n_candidates (and
    rel_heading when a heading column is given) to every point. Off-road points get empty
    road_id/lane_id/s/t and n_candidates 0."""
    import pyarrow as pa

    if points is None:
        raise fail("Missing option '--points'.", EXIT_USAGE)
    if output is not None and output.suffix.lower() not in (".csv", ".parquet", ".pq"):
        raise fail(f"{output}: unknown output format {output.suffix or '(no suffix)'!r}; use .csv or "
                   ".parquet", EXIT_USAGE)
    if map_file is None:
        raise fail("Missing argument 'MAP'.", EXIT_USAGE)
    if output is not None:
        check_output(output, overwrite)
    table = read_points(points)
    net = _load(map_file)
    x = table.column("x").to_numpy(zero_copy_only=False).astype(np.float64)
    y = table.column("y").to_numpy(zero_copy_only=False).astype(np.float64)
    heading = (table.column("heading").to_numpy(zero_copy_only=False).astype(np.float64)
               if "heading" in table.column_names else None)
    if track:
        tid = table.column("track_id").to_numpy(zero_copy_only=False) if "track_id" in table.column_names else None
        tm = table.column("time").to_numpy(zero_copy_only=False) if "time" in table.column_names else None
        proj = net.world_to_road_track(x, y, heading, tm, tid, drivable_only=drivable_only)
    else:
        proj = net.world_to_road(x, y, heading, drivable_only=drivable_only)
    on = proj.n_candidates > 0
    cols: dict[str, Any] = {
        "road_id": pa.array([str(r) if r is not None else None for r in proj.road_id], pa.string()),
        "lane_id": pa.array(proj.lane_id.astype(np.int16), mask=~on),
        "s": pa.array(proj.s, mask=~on),
        "t": pa.array(proj.t, mask=~on),
        "lane_offset": pa.array(proj.lane_offset, mask=~on),
        "n_candidates": pa.array(proj.n_candidates.astype(np.int32)),
    }
    if heading is not None:
        cols["rel_heading"] = pa.array(proj.rel_heading, mask=~on | ~np.isfinite(proj.rel_heading))
    for name, arr in cols.items():
        if name in table.column_names:
            table = table.remove_column(table.column_names.index(name))
        table = table.append_column(name, arr)
    write_table(table, output)
    n = len(x)
    err.print(f"projected {n:,} points onto {map_file.name}: {int(on.sum()):,} on a road, "
              f"{int((proj.n_candidates > 1).sum()):,} on several roads"
              + (f"; wrote {output}" if output else ""))


# ----------------------------------------------------------------------------------------------
# plot
@map_app.command("plot")
@handle_errors
def plot(
    map_file: Path = typer.Argument(None, metavar="MAP", help=_MAP_HELP),
    output: Path = typer.Option(None, "--output", "-o", help="The image (.png, .svg or .pdf)."),
    labels: bool = typer.Option(True, "--labels/--no-labels", help="Write road and junction ids."),
    junction_road_labels: bool = typer.Option(False, "--junction-road-labels", help="Also label "
                                              "the roads inside junctions."),
    dpi: int = typer.Option(150, "--dpi", min=20, max=1200, help="Resolution of a PNG."),
    step: float = typer.Option(1.0, "--step", min=0.05, help="Sampling of lane borders [m]."),
    overwrite: bool = overwrite_option(),
) -> None:
    """Draw the map: lanes filled by type, reference lines, road ids, junction outlines."""
    if output is None:
        raise fail("Missing option '--output' / '-o' (the image to write).", EXIT_USAGE)
    if output.suffix.lower() not in (".png", ".svg", ".pdf"):
        raise fail(f"{output}: unknown image format {output.suffix or '(no suffix)'!r}; use .png, .svg or "
                   ".pdf", EXIT_USAGE)
    check_output(output, overwrite)
    from aveas_format.errors import require
    from aveas_format.plot.map import save_map

    require("matplotlib", extra="plot", what="figures")  # says so before reading the map

    net = _load(map_file)

    save_map(net, output, dpi=dpi, labels=labels, junction_road_labels=junction_road_labels, step=step)
    err.print(f"wrote {output}")


# ----------------------------------------------------------------------------------------------
# check
@map_app.command("check")
@handle_errors
def check(
    map_file: Path = typer.Argument(None, metavar="MAP", help=_MAP_HELP),
    fmt: OutputFormat = format_option(OutputFormat.text, "-f", help="Report format: text or json."),
) -> None:
    """Self-consistency of a map: geometry continuity gaps, lane widths >= 0, broken links,
    unparseable geoReference. Exit 1 when there are errors."""
    net = _load(map_file)
    findings = net.check()
    counts = Counter(f.severity for f in findings)
    summary = {k: counts.get(k, 0) for k in ("error", "warning", "info")}
    if fmt is OutputFormat.json:
        print(json.dumps({
            "map": net.path,
            "valid": summary["error"] == 0,
            "counts": summary,
            "findings": [{"code": f.code, "severity": f.severity, "message": f.message, "road_id": f.road_id,
                          "line": f.line, "value": f.value} for f in findings],
        }, indent=2))
    else:
        for f in findings:
            loc = f" (line {f.line})" if f.line else ""
            print(f"{f.severity.upper():<8}{f.code:<24}{f.message}{loc}")
        verdict = "INVALID" if summary["error"] else "VALID"
        print(f"{verdict}: {summary['error']} errors, {summary['warning']} warnings, {summary['info']} info "
              f"({net.path or 'map'})")
    if summary["error"]:
        raise typer.Exit(EXIT_FINDINGS)


# ----------------------------------------------------------------------------------------------
# convert (Lanelet2 -> OpenDRIVE)
def _origin(text: str | None) -> tuple[float, float] | None:
    if text is None:
        return None
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise fail(f"--origin {text!r}: expected LAT,LON in degrees (e.g. 49.0,8.4)", EXIT_USAGE) from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise fail(f"--origin {text!r}: latitude or longitude out of range", EXIT_USAGE)
    return lat, lon


@map_app.command("convert")
@handle_errors
def convert(
    source: Path = typer.Argument(None, metavar="MAP.osm", help="The Lanelet2 map (OSM XML)."),
    output: Path = typer.Option(None, "--output", "-o", help="The OpenDRIVE map to write (.xodr)."),
    origin: str = typer.Option(None, "--origin", metavar="LAT,LON", help="Origin of the local frame "
                               "(default: the centre of the map's nodes)."),
    projection: str = typer.Option("tmerc", "--projection", help="tmerc: a transverse Mercator at the "
                                   "origin; utm: Lanelet2's UtmProjector (UTM minus the origin's UTM)."),
    tolerance: float = typer.Option(0.02, "--tolerance", min=0.001, help="Metres the lane borders may "
                                    "deviate from the lanelet bounds."),
    overwrite: bool = overwrite_option(),
    fmt: OutputFormat = format_option(),
) -> None:
    """Convert a Lanelet2 map to OpenDRIVE 1.8: lanelets -> lanes whose borders are their bounds,
    successors -> lane links, intersections -> junctions with connecting roads, traffic lights,
    stop lines, crosswalks and speed limits; the projection -> `<geoReference>`. Exit 1 when a
    lanelet could not be converted (each is named)."""
    if source is None:
        raise fail("Missing argument 'MAP.osm'.", EXIT_USAGE)
    if output is None:
        raise fail("Missing option '--output' / '-o' (the .xodr to write).", EXIT_USAGE)
    if projection not in ("tmerc", "utm"):
        raise fail(f"--projection {projection!r}: use tmerc or utm", EXIT_USAGE)
    check_output(output, overwrite)
    from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive

    conv = lanelet2_to_opendrive(source, origin=_origin(origin), projection_kind=projection, tol=tolerance)
    conv.write(output)
    lost = [w for w in conv.warnings if w.startswith("lanelet")]
    summary = {"map": str(source), "output": str(output), "lanelets": conv.lanelets,
               "converted_lanelets": len(conv.lanelet_lanes), "crosswalk_objects": len(conv.crosswalks),
               "roads": conv.roads, "junctions": conv.junctions, "signals": conv.signals,
               "areas_not_converted": conv.areas, "geo_reference": conv.geo_reference,
               "offset": list(conv.offset) if conv.offset else None, "origin": list(conv.origin),
               **conv.stats, "warnings": conv.warnings}
    if fmt is OutputFormat.json:
        print(json.dumps(summary, indent=2))
    else:
        for w in conv.warnings:
            err.print(f"warning: {w}")
        print_table([
            ("map", f"{source} -> {output}"),
            ("lanelets", f"{conv.lanelets}: {len(conv.lanelet_lanes)} as lanes, {len(conv.crosswalks)} "
             f"crosswalks as objects, {len(lost)} not converted"),
            ("roads", f"{conv.roads} ({conv.stats['connecting_roads']} connecting roads in {conv.junctions} "
             "junctions)"),
            ("lanes", f"{conv.stats['lanes']} in {conv.stats['lane_sections']} lane sections"),
            ("signals", str(conv.signals)),
            ("areas", f"{conv.areas} multipolygon areas (not lanes) left out"),
            ("frame", conv.geo_reference + (f" minus ({conv.offset[0]:.3f}, {conv.offset[1]:.3f})" if conv.offset else "")),
        ])
    if lost:
        raise typer.Exit(EXIT_FINDINGS)


# ----------------------------------------------------------------------------------------------
# build (a map from trajectories)
_VEHICLES = ("car", "van", "truck", "bus", "trailer", "motorcycle")


def _is_recording(path: Path) -> bool:
    return (path.is_dir() and (path / "recording.json").exists()) or path.name.endswith((".aveas", ".aveas.zip"))


def _tracks_of(path: Path):
    """x, y, track, time, heading (or None), vehicle mask, CRS and the opened recording (or None)
    of a recording or a tracks table (CSV/Parquet: track_id or participant_id, time, x, y[, heading,
    class])."""
    import pyarrow as pa

    from aveas_format.errors import FormatError

    if _is_recording(path):
        import aveas_format

        rec = aveas_format.open(path)
        s, p = rec.states, rec.participants
        pid = s.column("participant_id").to_numpy()
        cls = dict(zip(p.column("participant_id").to_pylist(), p.column("class").to_pylist()))
        vehicle = np.isin(np.array([cls.get(int(i), "car") for i in np.unique(pid)], dtype=object), _VEHICLES)
        vmask = vehicle[np.searchsorted(np.unique(pid), pid)]
        crs = rec.meta.crs or (rec.map.header.geo_reference if rec.map_source else None)
        return (s.column("x").to_numpy(), s.column("y").to_numpy(), pid, s.column("time").to_numpy(),
                s.column("heading").to_numpy(), vmask, crs, rec)
    table = read_points(path)
    names = table.column_names
    tcol = next((c for c in ("track_id", "participant_id", "id") if c in names), None)
    if tcol is None or "time" not in names:
        raise FormatError(f"a tracks table needs a track column (track_id, participant_id or id) and time; "
                          f"columns: {', '.join(names)}", path=path)
    track = table.column(tcol).cast(pa.string()).to_numpy(zero_copy_only=False)
    heading = table.column("heading").to_numpy(zero_copy_only=False).astype(float) if "heading" in names else None
    vmask = None
    for c in ("class", "agent_type"):
        if c in names:
            vmask = np.isin(np.array([str(v).lower() for v in table.column(c).to_pylist()], dtype=object), _VEHICLES)
    return (table.column("x").to_numpy(zero_copy_only=False).astype(float),
            table.column("y").to_numpy(zero_copy_only=False).astype(float), track,
            table.column("time").to_numpy(zero_copy_only=False).astype(float), heading, vmask, None, None)


@map_app.command("build")
@handle_errors
def build(
    source: Path = typer.Argument(None, metavar="REC_OR_TRACKS", help="A recording, or a tracks table "
                                  "(CSV/Parquet: track_id, time, x, y[, heading, class])."),
    output: Path = typer.Option(None, "--output", "-o", help="The OpenDRIVE map to write (.xodr)."),
    report: Path = typer.Option(None, "--report", help="Write the fit report (JSON) here."),
    reference: Path = typer.Option(None, "--reference", help="Also write the recording referenced "
                                   "against the built map here (a recording given as the input)."),
    geo_reference: str = typer.Option(None, "--geo-reference", help="The map's <geoReference> (default: "
                                      "the recording's CRS)."),
    tolerance: float = typer.Option(0.05, "--tolerance", min=0.001, help="Metres the lane borders may "
                                    "deviate from where the trajectories put them."),
    lane_width: float = typer.Option(3.5, "--lane-width", min=1.0, help="Width of a road's only lane."),
    min_tracks: int = typer.Option(3, "--min-tracks", min=1, help="Tracks a turning movement needs to "
                                   "become a connecting road."),
    figure: Path = typer.Option(None, "--figure", help="Draw the built lanes with the trajectories "
                                "over them and the residuals per lane (.png, .svg, .pdf)."),
    overwrite: bool = overwrite_option(),
    fmt: OutputFormat = format_option(),
) -> None:
    """Build an OpenDRIVE 1.8 map from the paths participants drive: carriageways and junctions
    from the flow of traffic, lanes per direction with their widths, lane sections where the lane
    count changes, one connecting road per driven turning movement; prints how well it fits (the
    lateral residuals of the trajectories per lane)."""
    if source is None:
        raise fail("Missing argument 'REC_OR_TRACKS'.", EXIT_USAGE)
    if output is None:
        raise fail("Missing option '--output' / '-o' (the .xodr to write).", EXIT_USAGE)
    outs = [output] + [p for p in (report, reference, figure) if p is not None]
    check_output(outs, overwrite)
    if figure is not None:
        from aveas_format.errors import require

        require("matplotlib", extra="plot", what="figures")
    if reference is not None and not _is_recording(source):
        raise fail("--reference needs a recording as the input (a tracks table has no recording to "
                   "reference)", EXIT_USAGE)
    from aveas_format.opendrive.roadfit.tracks import BuildOptions, map_from_tracks

    x, y, track, time, heading, vmask, crs, rec = _tracks_of(source)
    opts = BuildOptions(tol=tolerance, lane_width=lane_width, min_tracks=min_tracks)
    built = map_from_tracks(x, y, track, time, heading=heading, vehicle=vmask,
                            geo_reference=geo_reference or crs, options=opts,
                            name=f"built from {source.name}")
    built.write(output)
    summary = {"source": str(source), "output": str(output), "roads": built.roads, "junctions": built.junctions,
               "connecting_roads": built.connecting_roads, "lanes": built.lanes, **built.report}
    if report is not None:
        from aveas_format.safeio import write_text_atomic

        write_text_atomic(report, json.dumps(summary, indent=2))
    if reference is not None and rec is not None:
        _rereference(rec, built.xodr.encode(), reference, overwrite)
        summary["referenced"] = str(reference)
    if figure is not None:
        from aveas_format.plot.mapbuild import save_build

        keep = np.ones(len(x), dtype=bool) if vmask is None else np.asarray(vmask, dtype=bool)
        save_build(built.network(), figure, np.asarray(x)[keep], np.asarray(y)[keep],
                   None if heading is None else np.asarray(heading)[keep], title=f"built from {source.name}")
        summary["figure"] = str(figure)
    if fmt is OutputFormat.json:
        print(json.dumps(summary, indent=2))
        return
    print_table([
        ("map", f"{source} -> {output}"),
        ("roads", f"{built.roads} ({built.connecting_roads} connecting roads in {built.junctions} junctions)"),
        ("lanes", str(built.lanes)),
        ("points", f"{built.report['points']['used']:,} of {built.report['points']['given']:,} (moving vehicles)"),
        ("on a lane", f"{100 * built.report['on_lane_share']:.2f} %"),
        ("lateral", f"RMS {built.report['lateral_rms_m']} m, p95 {built.report['lateral_p95_m']} m from the "
                    "lane centres"),
    ] + [(f"road {ln['road_id']} lane {ln['lane_id']}", f"{ln['points']:,} points, RMS {ln['rms_m']} m, "
          f"p95 {ln['p95_m']} m") for ln in built.report["per_lane"]])


def _rereference(rec, xodr: bytes, path: Path, overwrite: bool) -> None:
    """Write ``rec`` with the built map and its states' road coordinates against it."""
    from aveas_format.mapref.roads import road_coordinates
    from aveas_format.opendrive import load_map

    s = rec.states
    net = load_map(xodr)
    cols = road_coordinates(net, s.column("participant_id").to_numpy(), s.column("time").to_numpy(),
                            s.column("x").to_numpy(), s.column("y").to_numpy(), s.column("heading").to_numpy())
    for name, arr in cols.items():
        if name in s.column_names:
            s = s.set_column(s.column_names.index(name), name, arr)
        else:
            s = s.append_column(name, arr)
    rec.replace_tables({"states": s})
    rec.map_source = xodr
    rec._map = None
    rec.write(path, overwrite=overwrite)
