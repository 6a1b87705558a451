"""Export/import throughput of the interoperability converters on the sample highway scene
(60 vehicles, 30 s at 25 Hz): OpenLABEL export + import (lossless round trip), OpenSCENARIO export
+ import (the storyboard replay), MCAP and OSI export."""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path


def main(n_vehicles: int = 60, duration_s: float = 30.0) -> list[dict]:
    from aveas_format.converters import convert, get_converter
    from aveas_format.sample import highway_scene

    rec = highway_scene(n_vehicles=n_vehicles, duration_s=duration_s)
    _ = rec.map  # parse once, outside the timings
    n = rec.states.num_rows
    tmp = Path(tempfile.mkdtemp(prefix="aveas-bench-interop-"))
    rows: list[dict] = []
    try:
        for name, file in (("openlabel", "rec.json"), ("openscenario", "rec.xosc"), ("mcap", "rec.mcap"),
                           ("osi", "rec.osi")):
            t0 = time.perf_counter()
            get_converter(name, "export")(rec, tmp / file)
            dt = time.perf_counter() - t0
            size = (tmp / file).stat().st_size
            rows.append({"benchmark": f"export_{name}", "states": n, "seconds": round(dt, 3),
                         "rows_per_s": round(n / dt), "note": f"{size / 1e6:.1f} MB"})
        t0 = time.perf_counter()
        back = convert("openlabel", [tmp / "rec.json"])
        dt = time.perf_counter() - t0
        rows.append({"benchmark": "import_openlabel", "states": back.states.num_rows,
                     "seconds": round(dt, 3), "rows_per_s": round(n / dt),
                     "note": "with the aveas_format extension (lossless)"})
        t0 = time.perf_counter()
        back = convert("openscenario", [tmp / "rec.xosc"])
        dt = time.perf_counter() - t0
        rows.append({"benchmark": "import_openscenario", "states": back.states.num_rows,
                     "seconds": round(dt, 3), "rows_per_s": round(back.states.num_rows / dt),
                     "note": "storyboard replay of the 10 Hz export (issue 18)"})
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return rows


if __name__ == "__main__":
    for r in main():
        print(r)
