"""Export/import throughput of the interoperability converters (issues 8, 22), each path as
states/s and MB beside a baseline measured in the same run.

The sample highway scene (60 vehicles, 30 s at 25 Hz, 23 k states): OpenLABEL export (streamed
from columns) against ``json.dumps`` of the same document and a pyarrow Parquet write of the same
states; OpenLABEL import (lossless) against ``json.loads`` of the same file and a Parquet read;
OpenSCENARIO export + import; OSI export (.osi, .mcap) against the bindings' per-object messages
and their floor, OSI import against betterosi's decoding alone, MCAP export against mcap's floor of
one message per state and a Parquet write. With ``--states N`` (e.g. 2000000) the scene is
tiled in time to N states (participant ids and times shifted, as bench_validate_memory does) and
the OpenLABEL export and import each run in a fresh process, with its peak memory (VmHWM) — the
recording is generated here, never stored in the repository. The compact forms (``.json.gz``,
``.json.zst``) are exported and imported on the sample; the import is compared with
``json.loads`` and ``msgspec.json.decode`` of the same bytes (best of 3 each).

    python benchmarks/bench_interop.py                 # the 23 k sample (make bench)
    python benchmarks/bench_interop.py --states 2000000
    python benchmarks/bench_interop.py --osi-mcap-states 2000000   # the OSI and MCAP rows alone
    python benchmarks/bench_interop.py --openlabel-states 2000000  # the OpenLABEL rows alone
"""

from __future__ import annotations

import filecmp
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_validate_memory import HWM_MB_SRC, tiled  # noqa: E402

_CHILD = """
import json, sys, time
from pathlib import Path
""" + HWM_MB_SRC + """
import aveas_format
from aveas_format.converters import convert, get_converter

what, rec_dir, out = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
n = None
# (the converters' plugins imported before the timing: ~0.8 s once per process, not the path's)
export, _ = get_converter("openlabel", "export"), get_converter("openlabel", "import")
if what in ("export", "export_disk"):  # the recording loaded / its states read from the file
    rec = aveas_format.open(rec_dir, states=what == "export")
    _ = rec.participants, rec.map
    base = hwm_mb()
    t0 = time.perf_counter()
    export(rec, out)
elif what == "parse":  # the floor of a Python-object reader: msgspec on the same frames, in blocks
    import msgspec
    from aveas_format.converters.openlabel import source

    base = hwm_mb()
    t0 = time.perf_counter()
    fr, n = source.open_frames(out), 0
    with source.open_file(out) as f:
        for _, data, kind in source.cuts(fr, f):
            if kind != "tail":
                n += sum(len(v.get("objects") or ()) for v in msgspec.json.decode(b"{" + data + b"}").values())
elif what in ("import_disk", "import_write"):  # the CLI's convert: written in parts / in memory + write
    from aveas_format.converters import convert_to

    target = out.parent / f"{what}.aveas"
    base = hwm_mb()
    t0 = time.perf_counter()
    if what == "import_disk":
        rec, n, _ = convert_to("openlabel", [out], target, options={"workers": 0})
    else:
        rec = convert("openlabel", [out], options={"workers": 0})
        rec.write(target)
else:
    base = hwm_mb()
    t0 = time.perf_counter()
    rec = convert("openlabel", [out], options={"workers": 1 if what != "import" else 0})
dt = time.perf_counter() - t0
import resource  # the worker processes' peak (the largest of them; ru_maxrss in KiB on Linux)
print(json.dumps({"seconds": dt, "peak_mb": hwm_mb(), "before_mb": base,
                  "workers_peak_mb": resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
                  "states": n if n is not None else rec.states.num_rows if rec.states is not None
                  else rec.meta.tables["states"].rows}))
"""


def _child(what: str, rec_dir: Path, out: Path, env: dict | None = None) -> dict:
    import os

    r = subprocess.run([sys.executable, "-c", _CHILD, what, str(rec_dir), str(out)],
                       capture_output=True, text=True, env={**os.environ, **(env or {})})
    if r.returncode:
        raise RuntimeError(r.stderr[-2000:])
    return json.loads(r.stdout.strip().splitlines()[-1])


def _row(name: str, n: int, dt: float, note: str, base_s: float | None = None, base_note: str = "") -> dict:
    r = {"benchmark": name, "states": n, "seconds": round(dt, 3), "rows_per_s": round(n / dt), "note": note}
    if base_s is not None:
        r["baseline_s"] = round(base_s, 3)
        r["speedup_vs_baseline"] = round(base_s / dt, 2)
        r["note"] = f"{note}; baseline: {base_note}"
    return r


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _best(fn, k: int = 3, *, gc_off: bool = False) -> float:
    """The best of ``k`` runs (the machine is shared: the least disturbed run); ``gc_off``: with the
    cyclic garbage collector paused, as the import runs (a fair baseline for parsing alone)."""
    import gc

    out = []
    for _ in range(k):
        gc.collect()
        if gc_off:
            gc.disable()
        try:
            out.append(_timed(fn))
        finally:
            gc.enable()
    return min(out)


def _load() -> str:
    try:
        return "load average " + Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "load average unknown"


def _openlabel_rows(rec, tmp: Path) -> list[dict]:
    """OpenLABEL export and import of ``rec`` in this process, with their same-run baselines."""
    import pyarrow.parquet as pq

    from aveas_format.converters import convert, get_converter
    from aveas_format.converters.openlabel import recording_to_openlabel
    from aveas_format.converters.openlabel.write import openlabel_chunks
    from aveas_format.safeio import write_parquet_atomic

    n = rec.states.num_rows
    out = tmp / "rec.json"
    dt = _timed(lambda: get_converter("openlabel", "export")(rec, out))
    mb = out.stat().st_size / 1e6
    enc = _timed(lambda: sum(map(len, openlabel_chunks(rec, opendrive="rec.xodr"))))
    doc = recording_to_openlabel(rec, opendrive="rec.xodr")
    b_dumps = _timed(lambda: json.dumps(doc, allow_nan=False, separators=(",", ":")).encode())
    del doc
    b_pq = _timed(lambda: write_parquet_atomic(rec.states, tmp / "states.parquet"))
    rows = [_row("encode_openlabel", n, enc, "the document's bytes from the recording, no file", b_dumps,
                 "json.dumps of the same document (built outside the timing)"),
            _row("export_openlabel", n, dt, f"{mb:.1f} MB ({mb * 1e3 / n:.2f} kB/state), streamed to the "
                 "file (atomic, fsync) + the map", b_pq,
                 f"pyarrow Parquet write of the states, atomic ({(tmp / 'states.parquet').stat().st_size / 1e6:.1f}"
                 " MB)")]
    dt = _best(lambda: convert("openlabel", [out]))
    dt1 = _best(lambda: convert("openlabel", [out], options={"workers": 1}))
    data = out.read_bytes()
    b_loads = _best(lambda: json.loads(data), gc_off=True)
    b_pqr = _best(lambda: pq.read_table(tmp / "states.parquet"))
    from aveas_format.parallel import default_workers

    rows += [_row("import_openlabel", n, dt, f"lossless (aveas_format extension), streamed, blocks in "
                  f"{default_workers()} worker processes, best of 3", dt1,
                  "the same import in one process (workers=1), best of 3"),
             _row("import_openlabel", n, dt, "(the same run)",
                  b_loads, "json.loads of the same bytes (no recording built, gc paused as in the import), best of 3"),
             _row("import_openlabel", n, dt, "(the same run)", b_pqr, "pyarrow Parquet read of the states")]
    import msgspec

    b_ms = _best(lambda: msgspec.json.decode(data), gc_off=True)
    rows.append(_row("import_openlabel", n, dt, "(the same run)", b_ms,
                     "msgspec.json.decode of the same bytes (no recording built, gc paused), best of 3"))
    del data
    rows += _compact_rows(rec, tmp, n, mb)
    return rows


def _compact_rows(rec, tmp: Path, n: int, plain_mb: float) -> list[dict]:
    """The compact forms (.json.gz, .json.zst where zstandard is installed): export and import."""
    import importlib.util

    from aveas_format.converters import convert, get_converter

    rows = []
    for suffix in (".json.gz", ".json.zst"):
        if suffix == ".json.zst" and importlib.util.find_spec("zstandard") is None:
            continue
        out = tmp / f"rec{suffix}"
        dt = _timed(lambda: get_converter("openlabel", "export")(rec, out))
        mb = out.stat().st_size / 1e6
        rows.append(_row(f"export_openlabel{suffix.replace('.', '_')}", n, dt,
                         f"{mb:.1f} MB ({plain_mb / mb:.1f}x smaller than the .json)"))
        dt = _best(lambda: convert("openlabel", [out]))
        rows.append(_row(f"import_openlabel{suffix.replace('.', '_')}", n, dt, "streamed, best of 3"))
    return rows


# ---- OSI and MCAP: the columnar protobuf encoder against the bindings, same run ---------------

def _osi_bindings(rec, map_reference: str = "") -> bytes:
    """The OSI export through the bindings (one betterosi message per moving object, serialized per
    time step, every GroundTruth naming the map written next to the trace): the same-run
    baseline; the columnar export writes the same bytes."""
    import math
    import struct
    import warnings

    import betterosi as b
    import numpy as np

    from aveas_format.converters.osi_export import _DEFAULT_HEIGHT, EXPORT_CLASS, _light_state
    from aveas_format.io.arrow import column_numpy

    st = rec.states
    pid, t = st["participant_id"].to_numpy(), column_numpy(st, "time")
    x, y, ax, ay = (column_numpy(st, c, missing=math.nan) for c in ("x", "y", "ax", "ay"))
    heading, vx, vy = (column_numpy(st, c, null=0.0, missing=0.0) for c in ("heading", "vx", "vy"))
    lights = [column_numpy(st, c, missing=math.nan) for c in
              ("light_brake_p", "light_indicator_left_p", "light_indicator_right_p", "light_hazard_p")]
    has_lights = any(np.isfinite(v).any() for v in lights)
    info = {p["participant_id"]: p for p in rec.participants.to_pylist()}
    host = next((q for q, p in info.items() if p.get("role") in ("system_under_test", "recording_vehicle")),
                None)

    def moving_object(i: int):
        p = info[int(pid[i])]
        otype, vtype = EXPORT_CLASS.get(p["class"], ("OTHER", None))
        h = p.get("height") or _DEFAULT_HEIGHT.get(p["class"], 1.5)
        kw = {"type": getattr(b.MovingObjectType, otype)}
        if vtype is not None:
            vc = {"type": getattr(b.MovingObjectVehicleClassificationType, vtype)}
            if has_lights:
                vc["light_state"] = _light_state(b, *(v[i] for v in lights))
            kw["vehicle_classification"] = b.MovingObjectVehicleClassification(**vc)
        acc = ({"acceleration": b.Vector3d(x=float(ax[i]), y=float(ay[i]), z=0.0)}
               if np.isfinite(ax[i]) else {})
        return b.MovingObject(id=b.Identifier(value=int(pid[i])), base=b.BaseMoving(
            dimension=b.Dimension3d(length=float(p["length"]), width=float(p["width"]), height=float(h)),
            position=b.Vector3d(x=float(x[i]), y=float(y[i]), z=float(h) / 2),
            orientation=b.Orientation3d(yaw=float(heading[i])),
            velocity=b.Vector3d(x=float(vx[i]), y=float(vy[i]), z=0.0), **acc), **kw)

    times = np.unique(t)
    order = np.lexsort((pid, t))
    bounds = np.r_[np.searchsorted(t[order], times), len(t)]
    out = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        for k in range(len(times)):
            sec, nanos = divmod(round(float(times[k]) * 1e9), 10**9)
            gt = b.GroundTruth(timestamp=b.Timestamp(seconds=sec, nanos=nanos),
                               moving_object=[moving_object(int(i)) for i in order[bounds[k]:bounds[k + 1]]],
                               proj_string=rec.meta.crs or "", map_reference=map_reference)
            if host is not None:
                gt.host_vehicle_id = b.Identifier(value=int(host))
            m = gt.to_binary()
            out.append(struct.pack("<I", len(m)) + m)
    return b"".join(out)


def _upb_fields(path: Path) -> float:
    """An alternative to the columnar decoder: the ``protobuf`` package's C
    (upb) backend with OSI classes made from betterosi's descriptor set, each object's fields the
    import reads accessed in Python (seconds)."""
    import os
    import struct

    import betterosi
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    raw = (Path(os.path.dirname(betterosi.__file__)) / "generated" / "3.8.0" /
           "osi3_descriptor_set.pb").read_bytes()
    pool = descriptor_pool.DescriptorPool()
    for fd in descriptor_pb2.FileDescriptorSet.FromString(raw).file:
        pool.Add(fd)
    gt_class = message_factory.GetMessageClass(pool.FindMessageTypeByName("osi3.GroundTruth"))
    data = path.read_bytes()

    def run() -> None:
        off, out = 0, []
        while off < len(data):
            (n,) = struct.unpack_from("<I", data, off)
            g = gt_class.FromString(data[off + 4:off + 4 + n])
            off += 4 + n
            t = g.timestamp.seconds + g.timestamp.nanos * 1e-9
            for mo in g.moving_object:
                q, vc = mo.base, mo.vehicle_classification
                out.append((t, q.position.x, q.position.y, q.position.z, q.orientation.yaw,
                            q.velocity.x, q.velocity.y, q.acceleration.x, q.acceleration.y,
                            q.orientation_rate.yaw, mo.id.value, mo.type, vc.type,
                            vc.light_state.brake_light_state, vc.light_state.indicator_state,
                            q.dimension.length, len(mo.assigned_lane_id)))

    return _best(run)


def _osi_mcap_rows(rec, tmp: Path) -> list[dict]:
    """OSI (.osi, .mcap) export and import, MCAP (Foxglove) export, each beside its same-run
    baseline, and the floors of the libraries: one near-empty OSI message built and serialized
    per state with the bindings; one empty MCAP message written per state with ``mcap``."""
    import warnings

    import betterosi as b
    import mcap.writer

    from aveas_format.converters import convert, get_converter

    n = rec.states.num_rows
    rows = []
    osi = get_converter("osi", "export")
    mc = get_converter("mcap", "export")
    osi(rec, tmp / "warm.osi")  # first calls outside the timings (imports, the map's lane polygons)
    convert("osi", [tmp / "warm.osi"], map_source=tmp / "warm.xodr")
    mc(rec, tmp / "warm.mcap")
    dt = _timed(lambda: osi(rec, tmp / "rec.osi"))
    b_old = _timed(lambda: _osi_bindings(rec, "rec.xodr"))
    same = _osi_bindings(rec, "rec.xodr") == (tmp / "rec.osi").read_bytes()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        floor = _timed(lambda: [b.MovingObject(id=b.Identifier(value=i)).to_binary() for i in range(n)])
    rows.append(_row("export_osi", n, dt, f"{(tmp / 'rec.osi').stat().st_size / 1e6:.1f} MB, bytes "
                     f"{'identical to' if same else 'DIFFERENT from'} the bindings' (+ the map)", b_old,
                     "the bindings: one betterosi message per object"))
    rows.append(_row("export_osi", n, dt, "(the same run)", floor, "floor of the bindings: one "
                     "MovingObject(id) built + serialized per state"))
    dt = _timed(lambda: osi(rec, tmp / "rec_osi.mcap"))
    rows.append(_row("export_osi_mcap", n, dt, f"{(tmp / 'rec_osi.mcap').stat().st_size / 1e6:.1f} MB"))
    import aveas_format.converters.osi as osi_mod
    from aveas_format.converters.common.fastpath import FastPathUnsupported

    dt = _best(lambda: convert("osi", [tmp / "rec.osi"], map_source=tmp / "rec.xodr"))
    dt_cols = _best(lambda: osi_mod._decode_columns([tmp / "rec.osi"], osi_mod.OsiOptions()))
    columns = osi_mod._decode_columns

    def columns_off(*a, **k):
        raise FastPathUnsupported("the betterosi path, for comparison")

    osi_mod._decode_columns = columns_off
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            dt_objects = _best(lambda: convert("osi", [tmp / "rec.osi"], map_source=tmp / "rec.xodr"))
    finally:
        osi_mod._decode_columns = columns
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        b_read = _timed(lambda: sum(len(g.moving_object) for g in
                                    b.read(str(tmp / "rec.osi"), return_ground_truth=True)))

    def touch() -> None:  # the fields the import reads, nothing kept (betterosi decodes lazily)
        for g in b.read(str(tmp / "rec.osi"), return_ground_truth=True):
            for mo in g.moving_object:
                q = mo.base
                _ = (mo.id.value, mo.type, q.position.x, q.position.y, q.position.z, q.orientation.yaw,
                     q.velocity, q.acceleration, q.orientation_rate, q.dimension.length,
                     mo.vehicle_classification, mo.assigned_lane_id)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        b_touch = _best(touch)
    rows.append(_row("import_osi", n, dt, "the recording, on its map (best of 3)", b_read,
                     "betterosi decoding the trace alone (sub-messages decoded lazily, not read)"))
    rows.append(_row("import_osi", n, dt, "(the same run)", b_touch,
                     "floor: betterosi decoding + reading each object's fields the import reads"))
    rows.append(_row("import_osi", n, dt, "(the same run)", dt_objects,
                     "the import decoding with betterosi instead of the columnar decoder"))
    rows.append(_row("decode_osi_columns", n, dt_cols, "the import's columnar decoder alone "
                     "(samples and per-object statics)", b_touch,
                     "betterosi decoding + reading the fields the import reads"))
    rows.append(_row("decode_osi_columns", n, dt_cols, "(the same run)", _upb_fields(tmp / "rec.osi"),
                     "the protobuf package's upb backend (classes from betterosi's descriptor set) "
                     "+ reading the same fields in Python"))
    dt = _timed(lambda: mc(rec, tmp / "rec.mcap"))
    dt_noloc = _timed(lambda: mc(rec, tmp / "rec_noloc.mcap", options={"locations": False}))

    def empty_messages() -> None:
        import io

        w = mcap.writer.Writer(io.BytesIO())
        w.start()
        ch = w.register_channel("/x", "protobuf", w.register_schema("x", "protobuf", b""))
        for i in range(n):
            w.add_message(ch, i, b"", i)
        w.finish()

    b_pq = _timed(lambda: __import__("aveas_format.safeio", fromlist=["x"]).write_parquet_atomic(
        rec.states, tmp / "mcap_baseline.parquet"))
    rows.append(_row("export_mcap", n, dt, f"{(tmp / 'rec.mcap').stat().st_size / 1e6:.1f} MB "
                     "(/scene + one /locations message per state)", _timed(empty_messages),
                     "floor of mcap: one empty message written per state"))
    rows.append(_row("export_mcap", n, dt, "(the same run)", b_pq, "pyarrow Parquet write of the states"))
    rows.append(_row("export_mcap_no_locations", n, dt_noloc,
                     f"{(tmp / 'rec_noloc.mcap').stat().st_size / 1e6:.1f} MB, /scene only (-O locations=false)"))
    return rows


def main(n_vehicles: int = 60, duration_s: float = 30.0) -> list[dict]:
    from aveas_format.converters import convert, get_converter
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=n_vehicles, duration_s=duration_s)
    _ = rec.map  # parse once, outside the timings
    n = rec.states.num_rows
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-interop-"))
    try:
        rows = _openlabel_rows(rec, tmp)
        rows += _osi_mcap_rows(rec, tmp)
        dt = _timed(lambda: get_converter("openscenario", "export")(rec, tmp / "rec.xosc"))
        rows.append(_row("export_openscenario", n, dt, f"{(tmp / 'rec.xosc').stat().st_size / 1e6:.1f} MB"))
        t0 = time.perf_counter()
        back = convert("openscenario", [tmp / "rec.xosc"])
        rows.append(_row("import_openscenario", back.states.num_rows, time.perf_counter() - t0,
                         "storyboard replay of the 10 Hz export (issue 18)"))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


def large(target_states: int) -> list[dict]:
    """The OpenLABEL export and import of a recording of ``target_states`` states, each in a fresh
    process (peak memory = its VmHWM; the export's includes the recording it reads), beside
    msgspec decoding the same frames in the import's blocks (nothing built), in a fresh process
    too."""
    from aveas_format.sample import highway_scene

    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-interop-large-"))
    try:
        base = highway_scene(n_vehicles=600, duration_s=300.0, seed=3)
        copies = max(1, -(-target_states // base.states.num_rows))
        rec = tiled(base, copies)
        rec.write(tmp / "rec")
        n = rec.states.num_rows
        del rec, base
        out = tmp / "rec.json"
        e = _child("export", tmp / "rec", out)
        mb = out.stat().st_size / 1e6
        (tmp / "disk").mkdir()
        ed = _child("export_disk", tmp / "rec", tmp / "disk" / "rec.json")
        if not filecmp.cmp(out, tmp / "disk" / "rec.json", shallow=False):
            raise RuntimeError("the export with the states read from the file wrote other bytes")
        (tmp / "disk" / "rec.json").unlink()
        i = _child("import", tmp / "rec", out)
        idisk = _child("import_disk", tmp / "rec", out)
        iwrite = _child("import_write", tmp / "rec", out)
        if not filecmp.cmp(tmp / "import_disk.aveas" / "states.parquet", tmp / "import_write.aveas" / "states.parquet",
                           shallow=False):
            raise RuntimeError("the import written in parts wrote other states than the import in memory")
        i1 = _child("import_1", tmp / "rec", out)
        rows = [
            _row("export_openlabel_large", n, e["seconds"], f"{mb:.0f} MB; frames in parts (one per core); "
                 f"fresh process: peak {e['peak_mb']:.0f} MB with the recording loaded ({e['before_mb']:.0f} MB "
                 f"before the export), the forked encoder at most {e['workers_peak_mb']:.0f} MB (shared pages "
                 f"of the recording counted)"),
            _row("export_openlabel_large", n, ed["seconds"], f"the states read from the file (the CLI's "
                 f"export): spilled in frame order, one bucket at a time; the same bytes; fresh process: peak "
                 f"{ed['peak_mb']:.0f} MB, the forked encoder at most {ed['workers_peak_mb']:.0f} MB",
                 e["seconds"], f"the recording loaded (peak {e['peak_mb']:.0f} MB)"),
            _row("import_openlabel_large", i["states"], i["seconds"],
                 f"blocks decoded in worker processes (one per core); fresh process: peak {i['peak_mb']:.0f} MB "
                 f"({i['before_mb']:.0f} MB after imports), each worker at most {i['workers_peak_mb']:.0f} MB",
                 i1["seconds"],
                 f"the same import in one process (workers=1), fresh process: peak {i1['peak_mb']:.0f} MB"),
        ]
        rows.append(_row("import_openlabel_to_disk", idisk["states"], idisk["seconds"],
                         f"the CLI's convert of one file: the boxes spilled, the states written a bucket of "
                         f"participants at a time (the same states.parquet, byte for byte); fresh process: peak "
                         f"{idisk['peak_mb']:.0f} MB, each worker at most {idisk['workers_peak_mb']:.0f} MB",
                         iwrite["seconds"], f"the import in memory + Recording.write (convert before), fresh "
                         f"process: peak {iwrite['peak_mb']:.0f} MB"))
        p = _child("parse", tmp / "rec", out)
        rows.append(_row("import_openlabel_large", i["states"], i["seconds"], "(the same run)", p["seconds"],
                         f"msgspec.json.decode of the same frames in the import's blocks, in one process, "
                         f"nothing built ({p['states']:,} boxes; peak {p['peak_mb']:.0f} MB)"))
        return rows
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


_CHILD_PROTO = """
import json, sys, time, warnings
from pathlib import Path
""" + HWM_MB_SRC + """
import aveas_format
from aveas_format.converters import get_converter

warnings.simplefilter("ignore")
name, rec_dir, out = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
if name in ("osi-import", "osi-import-betterosi"):  # the trace of an earlier child, on its map
    from aveas_format.converters import convert

    if name == "osi-import-betterosi":  # the import decoding with betterosi instead of the columnar decoder
        import aveas_format.converters.osi as osi_mod
        from aveas_format.converters.common.fastpath import FastPathUnsupported

        def _columns_off(*a, **k):
            raise FastPathUnsupported("the betterosi path, for comparison")

        osi_mod._decode_columns = _columns_off
    base = hwm_mb()
    t0 = time.perf_counter()
    n = convert("osi", [out], map_source=rec_dir / "map.xodr").states.num_rows
elif name == "osi-columns":  # the import's columnar decoder alone (samples and statics)
    import aveas_format.converters.osi as osi_mod

    from aveas_format.io.resort import StatesWriter

    base = hwm_mb()
    t0 = time.perf_counter()
    with StatesWriter(memory=None, key="oid") as w:
        osi_mod._decode_columns([out], osi_mod.OsiOptions(), osi_mod._Sink(w))
        n = w.rows
elif name == "osi-import-written":  # the CLI's convert: the states written in bounded memory
    from aveas_format.converters import convert_to

    base = hwm_mb()
    t0 = time.perf_counter()
    n = convert_to("osi", [out], rec_dir.parent / "written.aveas", map_source=rec_dir / "map.xodr")[1]
elif name == "osi-decode":  # floor of the import: betterosi decoding + the fields the import reads
    import betterosi as b

    base = hwm_mb()
    t0 = time.perf_counter()
    n = 0
    for g in b.read(str(out), return_ground_truth=True):
        for mo in g.moving_object:
            q = mo.base
            _ = (mo.id.value, mo.type, q.position.x, q.position.y, q.position.z, q.orientation.yaw,
                 q.velocity, q.acceleration, q.orientation_rate, q.dimension.length,
                 mo.vehicle_classification, mo.assigned_lane_id)
            n += 1
elif name in ("osi-floor", "mcap-floor"):  # floors of the exports, one item per state
    import pyarrow.parquet as pq

    n = pq.ParquetFile(rec_dir / "states.parquet").metadata.num_rows
    base = hwm_mb()
    t0 = time.perf_counter()
    if name == "osi-floor":  # the bindings: one MovingObject(id) built + serialized per state
        import betterosi as b

        for i in range(n):
            b.MovingObject(id=b.Identifier(value=i)).to_binary()
    else:  # mcap: one empty message written per state
        import mcap.writer

        with open(out, "wb") as f:
            w = mcap.writer.Writer(f)
            w.start()
            ch = w.register_channel("/x", "protobuf", w.register_schema("x", "protobuf", b""))
            for i in range(n):
                w.add_message(ch, i, b"", i)
            w.finish()
else:
    rec = aveas_format.open(rec_dir)
    _ = rec.states, rec.participants, rec.map
    n = rec.states.num_rows
    base = hwm_mb()
    t0 = time.perf_counter()
    get_converter(name, "export")(rec, out, options={"write_map": False} if name == "osi" else {})
dt = time.perf_counter() - t0
print(json.dumps({"seconds": dt, "peak_mb": hwm_mb(), "before_mb": base, "states": n}))
"""


def large_osi_mcap(target_states: int) -> list[dict]:
    """The OSI (.osi, .mcap) and MCAP exports of a recording of ``target_states`` states and the
    OSI import of the .osi trace, each in a fresh process (peak memory = its VmHWM; the exports'
    with the recording loaded)."""
    from aveas_format.sample import highway_scene

    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-interop-large-"))
    try:
        base = highway_scene(n_vehicles=600, duration_s=300.0, seed=3)
        rec = tiled(base, max(1, -(-target_states // base.states.num_rows)))
        rec.write(tmp / "rec")
        n = rec.states.num_rows
        del rec, base
        rows = []
        got = {}
        for name, file in (("osi", "rec.osi"), ("osi-floor", "none"), ("osi", "rec_osi.mcap"),
                           ("mcap", "rec.mcap"), ("mcap-floor", "floor.mcap"),
                           ("osi-import", "rec.osi"), ("osi-import-written", "rec.osi"),
                           ("osi-import-betterosi", "rec.osi"),
                           ("osi-columns", "rec.osi"), ("osi-decode", "rec.osi")):
            r = subprocess.run([sys.executable, "-c", _CHILD_PROTO, name, str(tmp / "rec"),
                                str(tmp / file)], capture_output=True, text=True)
            if r.returncode:
                raise RuntimeError(r.stderr[-2000:])
            e = got[(name, file)] = json.loads(r.stdout.strip().splitlines()[-1])
            if name in ("osi-import", "osi-import-written", "osi-import-betterosi", "osi-columns"):
                what = {"osi-import": "import_osi_large (.osi)",
                        "osi-import-written": "import_osi_large, written in bounded memory (convert_to)",
                        "osi-import-betterosi": "import_osi_large, decoded by betterosi (before 22f)",
                        "osi-columns": "decode_osi_columns_large (the decoder alone)"}[name]
                rows.append(_row(what, e["states"], e["seconds"],
                                 f"fresh process: peak {e['peak_mb']:.0f} MB ({e['before_mb']:.0f} MB "
                                 "after imports)"))
            elif name in ("osi", "mcap"):
                rows.append(_row(f"export_{name}_large ({Path(file).suffix})", n, e["seconds"],
                                 f"{(tmp / file).stat().st_size / 1e6:.0f} MB; fresh process: peak "
                                 f"{e['peak_mb']:.0f} MB ({e['before_mb']:.0f} MB with the recording "
                                 "loaded)"))
        floors = {"export_osi_large (.osi)": (("osi-floor", "none"), "floor of the bindings: one "
                                              "MovingObject(id) built + serialized per state (fresh process)"),
                  "export_mcap_large (.mcap)": (("mcap-floor", "floor.mcap"), "floor of mcap: one empty "
                                                "message written per state (fresh process)"),
                  "import_osi_large (.osi)": (("osi-decode", "rec.osi"), "floor: betterosi decoding + "
                                              "reading each object's fields the import reads (fresh process)"),
                  "decode_osi_columns_large (the decoder alone)": (
                      ("osi-decode", "rec.osi"), "betterosi decoding + reading the same fields (fresh "
                      "process)")}
        for r in list(rows):
            if r["benchmark"] in floors:
                key, note = floors[r["benchmark"]]
                rows.append(_row(r["benchmark"], r["states"], r["seconds"], "(the same run)",
                                 got[key]["seconds"], note))
        return rows
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    from gauge import machine_gauge

    print(machine_gauge(), "(at the start)")
    if len(sys.argv) > 2 and sys.argv[1] == "--osi-mcap-states":
        result = large_osi_mcap(int(sys.argv[2]))
    elif len(sys.argv) > 2 and sys.argv[1] == "--openlabel-states":
        result = large(int(sys.argv[2]))
    elif len(sys.argv) > 2 and sys.argv[1] == "--states":
        result = large(int(sys.argv[2])) + large_osi_mcap(int(sys.argv[2]))
    else:
        result = main()
    for r in result:
        print(r)
    print(_load(), "(at the end);", machine_gauge())
