"""Validating a dataset of 50 small synthetic recordings: 1 worker (in-process), 2 local worker
processes, and a local Dask cluster (2 worker processes, through ``--scheduler``'s code path).

Throughput is in recordings per second; the scaling ratio is each run's speed relative to one
worker (ideal: the number of workers). The process-pool runs include starting the pool; the Dask
cluster is started before timing (as an existing cluster would be), and its first run includes the
workers importing aveas-format.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path


def make_dataset(root: Path, n: int = 50) -> list[str]:
    from aveas_format.sample import highway_scene

    paths = []
    for i in range(n):
        rec = highway_scene(n_vehicles=8, duration_s=10.0, rate_hz=10.0, length_m=500.0, seed=i)
        paths.append(str(rec.write(root / f"partner{i % 3}" / f"rec{i:03d}.aveas")))
    return paths


def main(n: int = 50) -> list[dict]:
    from aveas_format import dataset as ds

    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-dataset-"))
    rows: list[dict] = []
    try:
        for p in ("partner0", "partner1", "partner2"):
            (tmp / p).mkdir()
        make_dataset(tmp, n)
        paths = ds.discover(tmp)
        assert len(paths) == n

        def run(**kw) -> float:
            t0 = time.perf_counter()
            rep = ds.validate_dataset(paths, **kw)
            dt = time.perf_counter() - t0
            assert rep.recordings == n and not rep.failed, rep.failed[:1]
            return dt

        run(workers=1, select=["structure"])  # warm imports of this process (rules, pyproj...)
        t1 = run(workers=1)

        def row(name: str, t: float, note: str) -> None:
            rows.append({"benchmark": f"dataset.{name}", "rows": n, "seconds": round(t, 3),
                         "rows_per_s": round(n / t, 1),
                         "baseline_s": None if name == "validate_1_worker" else round(t1, 3),
                         "speedup_vs_baseline": None if name == "validate_1_worker"
                         else round(t1 / t, 2), "note": note})

        row("validate_1_worker", t1, f"{n} recordings (8 vehicles, 10 s at 10 Hz), rows = "
            "recordings, in this process")
        t2 = run(workers=2)
        row("validate_2_workers", t2, "2 local processes incl. pool start; speedup = scaling ratio")
        try:
            import dask
            from distributed import LocalCluster
        except ImportError:
            rows.append({"benchmark": "dataset.validate_dask_2_workers", "rows": n,
                         "seconds": float("nan"), "note": "skipped: pip install "
                         "'aveas-format[dask]'"})
            return rows
        with dask.config.set({"distributed.worker.daemon": True, "logging.distributed": "error"}):
            with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster:
                addr = cluster.scheduler_address
                td_cold = run(scheduler=addr)
                td = run(scheduler=addr)
        row("validate_dask_2_workers_cold", td_cold, "LocalCluster, 2 worker processes; "
            "first run: the workers import aveas-format")
        row("validate_dask_2_workers", td, "LocalCluster, 2 worker processes, warm")
        load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
        rows[-1]["note"] += f" ({os.cpu_count()} cores, load average {load:.1f})"
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    for r in main():
        print(r)
