"""Validation throughput on a ~1M-row synthetic highway recording with its OpenDRIVE map.

Target (issue 4): the whole catalogue, map rules included, in <= 10 s for 1M state rows, read from
disk (checksums verified). Each rule family is also timed alone on the in-memory recording (it then
pays for the shared views it needs: the sorted states, the map evaluation, the pair search).
"""

from __future__ import annotations

import resource
import shutil
import tempfile
import time
from pathlib import Path


def main(n_vehicles: int = 1200, duration_s: float = 600.0) -> list[dict]:
    import aveas_format
    from aveas_format.sample import highway_scene
    from aveas_format.validate.registry import load_rules

    rec = highway_scene(n_vehicles=n_vehicles, duration_s=duration_s, seed=3)
    n = rec.states.num_rows
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-validate-"))
    rows: list[dict] = []

    def row(name: str, t: float, note: str = "") -> None:
        rows.append({"benchmark": f"validate.{name}", "rows": n, "seconds": round(t, 4),
                     "rows_per_s": round(n / t) if t > 0 else None, "baseline_s": None,
                     "speedup_vs_baseline": None, "note": note})

    try:
        path = rec.write(tmp / "bench.aveas")
        t0 = time.perf_counter()
        report = aveas_format.validate(path)
        total = time.perf_counter() - t0
        c = report.counts
        row("all_rules_from_disk", total,
            f"{len(report.rules_run)} rules; {c['error']} errors, {c['warning']} warnings, "
            f"{c['info']} info; target <= 10 s")
        for fam in sorted({r.family for r in load_rules().values()}):
            t0 = time.perf_counter()
            aveas_format.validate(rec, select=[fam])
            row(fam, time.perf_counter() - t0, "in memory, family alone")
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        rows.append({"benchmark": "validate.peak_rss", "rows": n, "seconds": 0.0,
                     "rows_per_s": None, "baseline_s": None, "speedup_vs_baseline": None,
                     "note": f"process peak RSS {peak:.0f} MB (includes building the recording)"})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    for r in main():
        print(r)
