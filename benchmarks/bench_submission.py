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
        return [
            _row("validate_openlabel_file", n, dt, f"{mb:.1f} MB OpenLABEL, import + "
                 f"{len(checked['rules_run'])} rules, report to a file (exit {code})", dt_schema,
                 f"jsonschema {_version('jsonschema')} on the ASAM OpenLABEL 1.0 schema alone, "
                 f"{n_sample} object-frames ({schema_frames} frames) scaled to {n:,}", n_sample),
            _row("validate_openlabel_file", n, dt, "(the same run): split below"),
            _row("  import_openlabel", n, dt_import, "the import alone (lossless)"),
            _row("  rules", n, dt_rules, "every rule on the imported recording (in memory)"),
            _row("validate_osi_file", n, dt_osi, f"{trace.stat().st_size / 1e6:.1f} MB ASAM OSI "
                 f"trace of the same scene, --map, import + rules (exit {code_osi})"),
        ]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _version(dist: str) -> str:
    from importlib.metadata import version

    return version(dist)


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    for r in main():
        print(r)
