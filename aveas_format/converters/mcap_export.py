"""Recording -> MCAP for Foxglove (visual inspection of the scene moving over its lanes).

``aveas-format export --to mcap REC -o rec.mcap`` writes an MCAP file with Protobuf messages of the
Foxglove schemas (PyPI ``foxglove-schemas-protobuf``, ``mcap``), log times = ``start_time`` +
``time``:

- ``/scene`` (``foxglove.SceneUpdate``), one message per distinct ``time``: per participant an
  entity ``participant/<id>`` in frame ``map`` (the recording's local frame) with a cube at the
  footprint centre (z lifted by half the height), yaw = ``heading``, size length x width x height,
  coloured by class, and a text label ``<id> <class>``; the entities' lifetime is 1.5 sample
  periods, so a participant disappears when its trajectory ends.
- ``/map`` (``foxglove.SceneUpdate``), one message at the start: the lane borders of the OpenDRIVE
  map as line strips (entity ``map/lanes``, drivable lanes white, others grey), lifetime forever.
- ``/unobserved`` (``foxglove.SceneUpdate``): the unobserved regions as closed red outlines for
  their validity intervals.
- ``/locations`` (``foxglove.LocationFix``): each participant's WGS 84 position per sample
  (``frame_id`` = participant id), for the Map panel; ``/origin``: the recording's location.

Open the file in Foxglove, add a 3D panel (display frame ``map``) and a Map panel.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from aveas_format.converters.registry import ConverterOptions, converter

#: class -> RGBA (0..1)
CLASS_COLOURS: dict[str, tuple[float, float, float, float]] = {
    "car": (0.20, 0.55, 0.95, 0.85), "van": (0.10, 0.75, 0.85, 0.85),
    "truck": (0.95, 0.55, 0.10, 0.85), "bus": (0.95, 0.80, 0.10, 0.85),
    "trailer": (0.80, 0.45, 0.20, 0.85), "motorcycle": (0.75, 0.25, 0.85, 0.85),
    "bicycle": (0.30, 0.85, 0.30, 0.85), "pedestrian": (0.95, 0.25, 0.35, 0.9),
    "mobility_device": (0.55, 0.90, 0.45, 0.85), "pushable_pullable": (0.65, 0.65, 0.30, 0.85),
    "railvehicle": (0.55, 0.35, 0.25, 0.85), "animal": (0.60, 0.40, 0.10, 0.85),
    "other": (0.70, 0.70, 0.70, 0.85),
}


class McapExportOptions(ConverterOptions):
    lane_step_m: float = 2.0
    """Sampling step of the lane borders (m)."""
    every: int = 1
    """Write every n-th time step of ``/scene`` (1 = all)."""
    locations: bool = True
    """Write ``/locations`` (one LocationFix per participant and sample)."""
    compression: str = "zstd"
    """Chunk compression: zstd, lz4 or none."""


def _file_descriptor_set(message_class) -> bytes:
    """The FileDescriptorSet (the MCAP protobuf schema) of a message class and its imports."""
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    fds = FileDescriptorSet()
    seen: set[str] = set()
    stack = [message_class.DESCRIPTOR.file]
    while stack:
        fd = stack.pop()
        if fd.name in seen:
            continue
        seen.add(fd.name)
        stack.extend(fd.dependencies)
        fd.CopyToProto(fds.file.add())
    return fds.SerializeToString()


def _ts(msg_field, ns: int) -> None:
    msg_field.seconds = ns // 1_000_000_000
    msg_field.nanos = ns % 1_000_000_000


@converter("mcap", direction="export", options=McapExportOptions,
           description="MCAP with Foxglove SceneUpdate boxes, lane lines and LocationFix",
           requires=("mcap", "foxglove_schemas_protobuf", "google.protobuf"), extra="mcap")
def export_mcap(rec, output: Path, *, options: McapExportOptions) -> list[Path]:
    import io

    import shapely

    # the [mcap] extra: checked by the registry (requires=) before this runs
    from foxglove_schemas_protobuf.Color_pb2 import Color
    from foxglove_schemas_protobuf.LinePrimitive_pb2 import LinePrimitive
    from foxglove_schemas_protobuf.LocationFix_pb2 import LocationFix
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from mcap.writer import CompressionType, Writer

    from aveas_format._version import __version__
    from aveas_format.safeio import write_bytes_atomic
    from aveas_format.schema.metadata import timestamp_ns

    t0 = timestamp_ns(rec.meta.start_time)
    buf = io.BytesIO()
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4,
            "none": CompressionType.NONE}[options.compression]
    w = Writer(buf, compression=comp)
    w.start(profile="", library=f"aveas-format {__version__}")
    scene_schema = w.register_schema("foxglove.SceneUpdate", "protobuf", _file_descriptor_set(SceneUpdate))
    fix_schema = w.register_schema("foxglove.LocationFix", "protobuf", _file_descriptor_set(LocationFix))
    ch_scene = w.register_channel("/scene", "protobuf", scene_schema)
    ch_map = w.register_channel("/map", "protobuf", scene_schema)
    ch_loc = w.register_channel("/locations", "protobuf", fix_schema) if options.locations else None
    ch_origin = w.register_channel("/origin", "protobuf", fix_schema)
    w.add_metadata("aveas", {"recording_id": rec.meta.recording_id, "crs": rec.meta.crs,
                             "start_time": rec.meta.start_time, "frame": "map"})

    # ---- map lanes ----------------------------------------------------------------------------
    up = SceneUpdate()
    ent = up.entities.add()
    _ts(ent.timestamp, t0)
    ent.frame_id = "map"
    ent.id = "map/lanes"
    try:
        polys = rec.map.lane_polygons(step=options.lane_step_m)
        drivable = {(r, sec, lid) for r, sec, lid, _ in rec.map.lane_polygons(
            step=options.lane_step_m * 10, drivable_only=True)}
    except Exception:  # noqa: BLE001 — a map the engine cannot sample: boxes only
        polys, drivable = [], set()
    for road, sec, lid, poly in polys:
        line = ent.lines.add()
        line.type = LinePrimitive.LINE_LOOP
        line.thickness = 0.12
        line.pose.orientation.w = 1.0
        c = (0.95, 0.95, 0.95, 0.9) if (road, sec, lid) in drivable else (0.5, 0.5, 0.5, 0.7)
        line.color.CopyFrom(Color(r=c[0], g=c[1], b=c[2], a=c[3]))
        for x, y in np.asarray(shapely.get_coordinates(poly.exterior))[:-1]:
            pt = line.points.add()
            pt.x, pt.y = float(x), float(y)
    w.add_message(ch_map, t0, up.SerializeToString(), t0)

    # ---- unobserved regions -------------------------------------------------------------------
    if rec.unobserved is not None and rec.unobserved.num_rows:
        ch_un = w.register_channel("/unobserved", "protobuf", scene_schema)
        for r in rec.unobserved.to_pylist():
            g = shapely.from_wkb(r["geometry"])
            u = SceneUpdate()
            e = u.entities.add()
            ns = t0 + int(round(r["time_start"] * 1e9))
            _ts(e.timestamp, ns)
            e.frame_id = "map"
            e.id = f"unobserved/{r['region_id']}"
            dur = int(round((r["time_end"] - r["time_start"]) * 1e9))
            _ts(e.lifetime, max(dur, 1))
            for part in getattr(g, "geoms", [g]):
                line = e.lines.add()
                line.type = LinePrimitive.LINE_LOOP
                line.thickness = 0.2
                line.pose.orientation.w = 1.0
                line.color.CopyFrom(Color(r=1.0, g=0.2, b=0.2, a=0.8))
                for x, y in np.asarray(shapely.get_coordinates(part.exterior))[:-1]:
                    pt = line.points.add()
                    pt.x, pt.y = float(x), float(y)
            w.add_message(ch_un, ns, u.SerializeToString(), ns)

    # ---- boxes ----------------------------------------------------------------------------------
    p = rec.participants
    s = rec.states
    info = {}
    hcol = p.column("height").to_pylist() if "height" in p.column_names else [None] * p.num_rows
    for q, cls, ln, wd, hh in zip(p.column("participant_id").to_pylist(),
                                  p.column("class").cast("string").to_pylist(),
                                  p.column("length").to_pylist(), p.column("width").to_pylist(), hcol):
        info[q] = (cls, ln, wd, hh if hh else 1.5)
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    x, y, h = (s.column(c).to_numpy() for c in ("x", "y", "heading"))
    z = (np.nan_to_num(s.column("z").to_numpy(zero_copy_only=False).astype(float))
         if "z" in s.column_names else np.zeros(len(t)))
    times, inv = np.unique(t, return_inverse=True)
    period = float(np.median(np.diff(times))) if len(times) > 1 else 1.0 / rec.meta.nominal_rate_hz
    life = int(round(1.5 * period * max(options.every, 1) * 1e9))
    order = np.argsort(inv, kind="stable")
    bounds = np.searchsorted(inv[order], np.arange(len(times) + 1))
    for k in range(0, len(times), max(options.every, 1)):
        ns = t0 + int(round(times[k] * 1e9))
        up = SceneUpdate()
        for i in order[bounds[k]:bounds[k + 1]]:
            q = int(pid[i])
            cls, ln, wd, hh = info[q]
            e = up.entities.add()
            _ts(e.timestamp, ns)
            _ts(e.lifetime, life)
            e.frame_id = "map"
            e.id = f"participant/{q}"
            cube = e.cubes.add()
            cube.pose.position.x, cube.pose.position.y = float(x[i]), float(y[i])
            cube.pose.position.z = float(z[i] + hh / 2)
            cube.pose.orientation.z = float(np.sin(h[i] / 2))
            cube.pose.orientation.w = float(np.cos(h[i] / 2))
            cube.size.x, cube.size.y, cube.size.z = float(ln), float(wd), float(hh)
            c = CLASS_COLOURS.get(cls, CLASS_COLOURS["other"])
            cube.color.CopyFrom(Color(r=c[0], g=c[1], b=c[2], a=c[3]))
            txt = e.texts.add()
            txt.pose.position.x, txt.pose.position.y = float(x[i]), float(y[i])
            txt.pose.position.z = float(z[i] + hh + 0.5)
            txt.pose.orientation.w = 1.0
            txt.billboard = True
            txt.font_size = 14.0
            txt.scale_invariant = True
            txt.color.CopyFrom(Color(r=1, g=1, b=1, a=1))
            txt.text = f"{q} {cls}"
            e.metadata.add(key="class", value=cls)
        w.add_message(ch_scene, ns, up.SerializeToString(), ns)

    # ---- geo --------------------------------------------------------------------------------------
    loc = rec.meta.location
    fix = LocationFix(latitude=loc.lat, longitude=loc.lon, altitude=loc.alt or 0.0, frame_id="origin")
    _ts(fix.timestamp, t0)
    w.add_message(ch_origin, t0, fix.SerializeToString(), t0)
    if ch_loc is not None:
        lon, lat = s.column("lon").to_numpy(), s.column("lat").to_numpy()
        for i in np.argsort(t, kind="stable"):
            ns = t0 + int(round(t[i] * 1e9))
            f = LocationFix(latitude=float(lat[i]), longitude=float(lon[i]), frame_id=str(int(pid[i])),
                            position_covariance_type=LocationFix.UNKNOWN)
            _ts(f.timestamp, ns)
            f.color.CopyFrom(Color(**dict(zip("rgba", CLASS_COLOURS.get(info[int(pid[i])][0],
                                                                          CLASS_COLOURS["other"])))))
            w.add_message(ch_loc, ns, f.SerializeToString(), ns)
    w.finish()
    return [write_bytes_atomic(Path(output), buf.getvalue())]


__all__ = ["CLASS_COLOURS", "export_mcap"]
