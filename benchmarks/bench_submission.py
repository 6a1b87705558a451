"""``aveas-format validate FILE`` on a submitted OpenLABEL file, end to end (issue 22), in
object-frames/s (one object in one frame = one state), beside what the official schema check alone
achieves in the same run: ``jsonschema`` on the ASAM OpenLABEL 1.0 JSON schema (shipped by
``uai-openlabel``) on a small sample of the same file's frames.

The sample highway scene (60 vehicles, 30 s at 25 Hz, 23 k states) is exported to OpenLABEL (with
its map next to it), then checked the way a partner's file is: the CLI in this process
(``validate FILE --format json -o report.json``: import with the source findings collected, every
rule). The split: the import alone and the rules alone on the imported recording. And the same
scene as an ASAM OSI trace, checked the same way (``validate TRACE --map MAP``).

    python benchmarks/bench_submission.py
    python benchmarks/bench_submission.py --states 2000000

With ``--states N`` the scene of bench_interop's large rows (600 vehicles, 5 min, tiled in time to
N states; generated here, never stored) is exported and checked by ``aveas-format validate`` in a
fresh process (peak memory = its VmHWM), the import alone in another, beside the jsonschema
baseline measured on a sample of the same file's frames in this process.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path


def _row(name: str, n: int, dt: float, note: str, base_s: float | None = None,
         base_note: str = "", base_n: int | None = None) -> dict:
    """``base_n``: the baseline's own count (a sample); its time is scaled to ``n`` rows."""
    r = {"benchmark": name, "states": n, "seconds": round(dt, 3), "rows_per_s": round(n / dt),
         "note": note}
    if base_s is not None:
        scaled = base_s * n / base_n if base_n else base_s
        r["baseline_s"] = round(scaled, 3)
        r["speedup_vs_baseline"] = round(scaled / dt, 1)
        r["note"] = f"{note}; baseline: {base_note}"
    return r


def _schema_sample(doc: dict, frames: int) -> tuple[dict, int]:
    """The document with its first ``frames`` frames, and their object-frames."""
    ol = dict(doc["openlabel"])
    keys = list(ol["frames"])[:frames]
    ol["frames"] = {k: ol["frames"][k] for k in keys}
    ol.pop("frame_intervals", None)
    n = sum(len(f.get("objects", {})) for f in ol["frames"].values())
    return {"openlabel": ol}, n


def main(n_vehicles: int = 60, duration_s: float = 30.0, schema_frames: int = 10) -> list[dict]:
    import jsonschema

    import aveas_format
    from aveas_format.cli.app import app
    from aveas_format.cli.common import run
    from aveas_format.converters import convert, get_converter
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=n_vehicles, duration_s=duration_s)
    n = rec.states.num_rows
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-submission-"))
    try:
        src = tmp / "submission.json"
        get_converter("openlabel", "export")(rec, src)
        del rec
        report = tmp / "report.json"
        t0 = time.perf_counter()
        code = run(app, ["validate", str(src), "--format", "json", "-o", str(report)])
        dt = time.perf_counter() - t0
        checked = json.loads(report.read_text())
        assert code in (0, 1), f"validate exited {code}"
        warm = {}  # the same again with the modules loaded: in worker processes, then in this one
        for w in ("0", "1"):
            t0 = time.perf_counter()
            run(app, ["validate", str(src), "--workers", w, "--format", "json", "-o", str(report),
                      "--overwrite"])
            warm[w] = time.perf_counter() - t0
        t0 = time.perf_counter()
        imported = convert("openlabel", [src])
        dt_import = time.perf_counter() - t0
        dt_rules = _timed(lambda: aveas_format.validate(imported))

        import uai_openlabel

        schema_path = Path(uai_openlabel.__file__).parent / "official_schema" / "openlabel_json_schema.json"
        schema = json.loads(schema_path.read_text())
        validator = jsonschema.validators.validator_for(schema)(schema)
        sample, n_sample = _schema_sample(json.loads(src.read_bytes()), schema_frames)
        dt_schema = _timed(lambda: validator.validate(sample))
        mb = src.stat().st_size / 1e6
        trace = tmp / "submission.osi"
        get_converter("osi", "export")(imported, trace)
        t0 = time.perf_counter()
        code_osi = run(app, ["validate", str(trace), "--map", str(tmp / "submission.xodr"),
                             "--format", "json", "-o", str(tmp / "report_osi.json")])
        dt_osi = time.perf_counter() - t0
        from aveas_format.parallel import default_workers

        return [
            _row("validate_openlabel_file", n, dt, f"{mb:.1f} MB OpenLABEL, import + "
                 f"{len(checked['rules_run'])} rules, report to a file (exit {code})", dt_schema,
                 f"jsonschema {_version('jsonschema')} on the ASAM OpenLABEL 1.0 schema alone, "
                 f"{n_sample} object-frames ({schema_frames} frames) scaled to {n:,}", n_sample),
            _row("validate_openlabel_file", n, warm["0"], f"again, modules loaded; the frames read in "
                 f"{default_workers()} worker processes", warm["1"], "the same with --workers 1 (in one process)"),
            _row("validate_openlabel_file", n, dt, "(the same run): split below"),
            _row("  import_openlabel", n, dt_import, "the import alone (lossless)"),
            _row("  rules", n, dt_rules, "every rule on the imported recording (in memory)"),
            _row("validate_osi_file", n, dt_osi, f"{trace.stat().st_size / 1e6:.1f} MB ASAM OSI "
                 f"trace of the same scene, --map, import + rules (exit {code_osi})"),
        ]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


_CHILD = """
import json, sys, time
""" + "{hwm}" + """
what, src = sys.argv[1], sys.argv[2]
t0 = time.perf_counter()
if what == "validate":
    from aveas_format.cli.app import app
    from aveas_format.cli.common import run

    code = run(app, ["validate", src, "--format", "json", "-o", sys.argv[3], "--overwrite",
                     "--workers", sys.argv[4]])
    extra = {"exit": code, "rules": len(json.loads(open(sys.argv[3]).read())["rules_run"])}
else:
    from aveas_format.converters import convert

    extra = {"states": convert("openlabel", [src]).states.num_rows}
print(json.dumps({"seconds": time.perf_counter() - t0, "peak_mb": hwm_mb(), **extra}))
"""


def large(target_states: int, schema_frames: int = 2) -> list[dict]:
    """``validate FILE`` on an OpenLABEL file of ``target_states`` states in a fresh process, and
    the import alone in another, beside jsonschema on a sample of its frames."""
    import subprocess

    import jsonschema

    from bench_validate_memory import HWM_MB_SRC, tiled

    from aveas_format.converters import get_converter
    from aveas_format.sample import highway_scene

    child = _CHILD.replace("{hwm}", HWM_MB_SRC)
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-submission-large-"))
    try:
        base = highway_scene(n_vehicles=600, duration_s=300.0, seed=3)
        rec = tiled(base, max(1, -(-target_states // base.states.num_rows)))
        n = rec.states.num_rows
        src = tmp / "submission.json"
        get_converter("openlabel", "export")(rec, src)
        del rec, base
        out = {}
        for what, workers in (("validate", "0"), ("validate_1", "1"), ("import", "0")):
            r = subprocess.run([sys.executable, "-c", child, what.split("_")[0], str(src),
                                str(tmp / "report.json"), workers], capture_output=True, text=True)
            if r.returncode:
                raise RuntimeError(r.stderr[-2000:])
            out[what] = json.loads(r.stdout.strip().splitlines()[-1])
        # the schema baseline: the first frames of the same file (read whole only up to them)
        import uai_openlabel

        schema_path = Path(uai_openlabel.__file__).parent / "official_schema" / "openlabel_json_schema.json"
        schema = json.loads(schema_path.read_text())
        validator = jsonschema.validators.validator_for(schema)(schema)
        sample, n_sample = _first_frames(src, schema_frames)
        dt_schema = _timed(lambda: validator.validate(sample))
        v, i = out["validate"], out["import"]
        mb = src.stat().st_size / 1e6
        return [
            _row("validate_openlabel_file_large", n, v["seconds"], f"{mb:.0f} MB OpenLABEL, import + "
                 f"{v['rules']} rules, report to a file (exit {v['exit']}); fresh process: peak "
                 f"{v['peak_mb']:.0f} MB", dt_schema,
                 f"jsonschema on the ASAM OpenLABEL 1.0 schema alone, {n_sample} object-frames "
                 f"({schema_frames} frames) scaled to {n:,}", n_sample),
            _row("validate_openlabel_file_large", n, v["seconds"], "(the same run; the frames read in "
                 "worker processes, one per core)", out["validate_1"]["seconds"], "the same with --workers 1, "
                 f"fresh process: peak {out['validate_1']['peak_mb']:.0f} MB"),
            _row("  import_openlabel_large", n, i["seconds"], f"the import alone, fresh process: peak "
                 f"{i['peak_mb']:.0f} MB"),
        ]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _first_frames(src: Path, frames: int) -> tuple[dict, int]:
    """The document of ``src`` with its first ``frames`` frames (from the import's blocks) and their
    object-frames."""
    import msgspec

    from aveas_format.converters.openlabel import source

    fr = source.open_frames(src)
    ol = dict(fr.head)
    ol["frames"] = {}
    with source.open_file(src) as f:
        for _, data, kind in source.cuts(fr, f):
            if kind != "tail":
                for k, v in msgspec.json.decode(b"{" + data + b"}").items():
                    if len(ol["frames"]) < frames:
                        ol["frames"][k] = v
            if len(ol["frames"]) == frames:
                break
    ol.pop("frame_intervals", None)
    n = sum(len(f.get("objects", {})) for f in ol["frames"].values())
    return {"openlabel": ol}, n


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    rows = large(int(sys.argv[2])) if len(sys.argv) > 2 and sys.argv[1] == "--states" else main()
    for r in rows:
        print(r)
    try:
        print("load average", Path("/proc/loadavg").read_text().split()[0], "(at the end)")
    except OSError:
        pass
