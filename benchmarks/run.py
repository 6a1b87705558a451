"""`make bench`: every benchmark, each printed with its baseline measured in the same run."""

from __future__ import annotations

import importlib.util
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _load(name: str):
    spec = importlib.util.spec_from_file_location(name, HERE / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    assert spec.loader is not None
    spec.loader.exec_module(mod)
    return mod


def format_row(r: dict) -> str:
    """One result line: name, seconds, rows/s, the same-run baseline and its ratio, a note."""
    base = r.get("baseline_s")
    ratio = r.get("speedup_vs_baseline")
    extra = f"  baseline {base} s -> {ratio}x" if base is not None else ""
    secs = r.get("seconds")
    secs_txt = f"{secs:>9.4f} s" if isinstance(secs, (int, float)) else f"{'':>11}"
    rate = r.get("rows_per_s")
    rate_txt = f"{rate:>12,.0f} rows/s" if isinstance(rate, (int, float)) else f"{'':>19}"
    return f"{r.get('benchmark', '?'):<32} {secs_txt}  {rate_txt}{extra}  {r.get('note', '')}"


def main() -> int:
    import os

    print(f"# aveas-format benchmarks — {platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, Python {platform.python_version()}, {time.strftime('%Y-%m-%d')}")
    print(f"# {_load('gauge').machine_gauge()}")
    for name in sorted(p.stem for p in HERE.glob("bench_*.py")):
        print(f"\n## {name}")
        t0 = time.perf_counter()
        rows = _load(name).main()
        for r in rows or []:
            print(format_row(r))
        print(f"({time.perf_counter() - t0:.1f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
