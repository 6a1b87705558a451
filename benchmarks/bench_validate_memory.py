"""Peak memory of `validate` on a 10M-row recording, streamed in batches (issue 4, issue 11).

Target: peak RSS <= 2 GB for 10M state rows (all rules, map included). The recording is the ~0.5M-row
synthetic highway scene repeated one after the other (participant ids and times shifted:
a 100-minute recording on the same road). Each validation runs in a fresh subprocess, so its peak
RSS is its own (building the recording is not counted). Baseline in the same run: the same
validation of three copies (~3M rows) loaded whole (streaming off), against the streamed one.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: source of ``hwm_mb()`` for the fresh processes of the memory benchmarks (also bench_interop)
HWM_MB_SRC = """
def hwm_mb():
    # VmHWM belongs to this process's own address space; ru_maxrss would also count the parent's
    # memory at fork (Linux keeps it across exec)
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")
"""

_CHILD = """
import json, sys, time
import aveas_format
""" + HWM_MB_SRC + """
cfg = json.loads(sys.argv[2])
t0 = time.perf_counter()
r = aveas_format.validate(sys.argv[1], config=cfg)
dt = time.perf_counter() - t0
print(json.dumps({"seconds": dt, "peak_mb": hwm_mb(),
                  "streamed": r.streamed, "counts": r.counts, "failures": len(r.failures)}))
"""


def _validate(path: Path, config: dict) -> dict:
    out = subprocess.run([sys.executable, "-c", _CHILD, str(path), json.dumps(config)],
                         capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def tiled(rec, copies: int):
    """Recording ``rec`` repeated ``copies`` times in time (ids and times shifted)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from aveas_format.io.recording import Recording

    duration_s = rec.meta.duration_s
    step = int(pc.max(rec.participants.column("participant_id")).as_py()) + 1

    def shifted(t: pa.Table, k: int, with_time: bool) -> pa.Table:
        i = t.schema.get_field_index("participant_id")
        t = t.set_column(i, "participant_id", pc.add(t.column(i), k * step))
        if with_time:
            j = t.schema.get_field_index("time")
            t = t.set_column(j, "time", pc.add(t.column(j), k * duration_s))
        return t

    states = pa.concat_tables([shifted(rec.states, k, True) for k in range(copies)])
    parts = pa.concat_tables([shifted(rec.participants, k, False) for k in range(copies)])
    meta = rec.meta.model_copy(update={"duration_s": duration_s * copies})
    return Recording(meta=meta, tables={"participants": parts, "states": states},
                     map_source=rec.map_source)


def main(target_rows: int = 10_000_000) -> list[dict]:
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-validate-mem-"))
    rows: list[dict] = []
    try:
        from aveas_format.sample import highway_scene

        t0 = time.perf_counter()
        base = highway_scene(n_vehicles=1200, duration_s=600.0, seed=3)
        copies = -(-target_rows // base.states.num_rows)
        big = tiled(base, copies)
        n = big.states.num_rows
        path = big.write(tmp / "big.aveas")
        del big
        small = tiled(base, -(-3_000_000 // base.states.num_rows))
        n2 = small.states.num_rows
        path2 = small.write(tmp / "small.aveas")
        del small, base
        build = time.perf_counter() - t0

        streamed = _validate(path, {})
        rows.append({"benchmark": "validate.streamed_10M", "rows": n,
                     "seconds": round(streamed["seconds"], 2),
                     "rows_per_s": round(n / streamed["seconds"]), "baseline_s": None,
                     "speedup_vs_baseline": None,
                     "note": f"peak RSS {streamed['peak_mb']:.0f} MB (target <= 2048 MB); batches "
                             f"{streamed['streamed']}; findings {streamed['counts']}; "
                             f"failures {streamed['failures']}; building took {build:.0f} s"})
        whole = _validate(path2, {"streaming": {"above_rows": 10**12}})
        part = _validate(path2, {})
        rows.append({"benchmark": "validate.streamed_vs_whole_3M", "rows": n2,
                     "seconds": round(part["seconds"], 2),
                     "rows_per_s": round(n2 / part["seconds"]),
                     "baseline_s": round(whole["seconds"], 2),
                     "speedup_vs_baseline": round(whole["seconds"] / part["seconds"], 2),
                     "note": f"peak RSS streamed {part['peak_mb']:.0f} MB vs loaded whole "
                             f"{whole['peak_mb']:.0f} MB (memory ratio "
                             f"{whole['peak_mb'] / part['peak_mb']:.2f})"})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    for r in main(int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000):
        print(r)
