"""Write/read throughput of a 1M-row recording, next to a pandas CSV baseline in the same run.

Targets (issue 2, on a 2-core machine): write <= 1.5 s and read of all columns <= 0.5 s for
1,000 participants x 1,000 steps (1M state rows with `_std` columns).
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np


def _best(fn, repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main(n_participants: int = 1000, n_steps: int = 1000) -> list[dict]:
    import pandas as pd

    import aveas_format
    from aveas_format.io.recording import Recording
    from aveas_format.sample import synthetic_states
    from aveas_format.schema import RecordingMeta

    ROOT = Path(__file__).resolve().parent.parent
    states = synthetic_states(n_participants, n_steps)
    n = states.num_rows
    participants = {
        "participant_id": np.arange(n_participants, dtype=np.int64),
        "source_id": [str(i) for i in range(n_participants)],
        "class": ["car"] * n_participants, "length": np.full(n_participants, 4.5),
        "width": np.full(n_participants, 1.8), "role": ["observed"] * n_participants,
        "provenance": ["natural"] * n_participants,
    }
    import pyarrow as pa

    meta = RecordingMeta.model_validate({
        "format_version": "1.0.0", "recording_id": "bench", "start_time": "2024-01-01T00:00:00Z",
        "duration_s": n_steps / 25.0, "nominal_rate_hz": 25.0,
        "acquisition": {"method": "aerial", "partner": "bench"}, "provenance": "natural",
        "location": {"lon": 8.35, "lat": 48.9}, "crs": "EPSG:4326",
        "map": {"file": "map.xodr", "sha256": "0" * 64, "opendrive_version": "1.6"},
        "rights": {"right_of_use": "research_only", "license": "x", "owner": "x"}, "tables": {},
    })
    rec = Recording(meta, {"participants": pa.table(participants), "states": states},
                    (ROOT / "tests" / "data" / "straight.xodr").read_bytes())
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-"))
    rows = []
    try:
        target = tmp / "bench.aveas"

        def write():
            rec.write(target, overwrite=True)

        t_write = _best(write)
        size = sum(f.stat().st_size for f in target.iterdir())
        t_read = _best(lambda: aveas_format.open(target))
        t_read_cols = _best(lambda: aveas_format.open(target, columns=["x", "y"], verify=False))
        t_read_pid = _best(lambda: aveas_format.open(target, participants=[17, 500]))

        df = states.to_pandas()
        csv = tmp / "states.csv"
        t_csv_write = _best(lambda: df.to_csv(csv, index=False), repeat=1)
        t_csv_read = _best(lambda: pd.read_csv(csv), repeat=1)
        csv_size = csv.stat().st_size
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    def row(op, t, base=None, note=""):
        r = {"benchmark": f"io.{op}", "rows": n, "seconds": round(t, 4),
             "rows_per_s": round(n / t), "baseline_s": None if base is None else round(base, 4),
             "speedup_vs_baseline": None if base is None else round(base / t, 1), "note": note}
        rows.append(r)

    row("write", t_write, t_csv_write, f"{size / 1e6:.1f} MB Parquet vs {csv_size / 1e6:.1f} MB CSV; "
        "target <= 1.5 s")
    row("read_all", t_read, t_csv_read, "all tables, all columns, SHA-256 verified; target <= 0.5 s")
    row("read_2_columns", t_read_cols, t_csv_read, "states x, y (+ keys)")
    row("read_2_participants", t_read_pid, t_csv_read, "row-group statistics skip the rest")
    return rows


if __name__ == "__main__":
    for r in main():
        print(r)
