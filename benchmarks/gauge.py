"""How fast this machine is right now, for reading numbers of different days side by side.

Machines, and one machine under other work, differ by 2-5x in speed (a CPython loop at 5-30 M
iterations/s), more than most changes measured here. Each benchmark has its baseline in the same
run (read the ratios); this gauge, printed at the head of ``make bench`` and of the large runs,
says what kind of machine gave the seconds.
"""

from __future__ import annotations

import hashlib
import time

import numpy as np


def machine_gauge() -> str:
    """One line: a CPython loop (M iterations/s), NumPy writing 256 MiB (GB/s), SHA-256 (MB/s);
    best of 3 each (~1-2 s in all)."""

    def best(fn) -> float:
        out = []
        for _ in range(3):
            t = time.perf_counter()
            fn()
            out.append(time.perf_counter() - t)
        return min(out)

    def loop() -> None:
        s = 0
        for i in range(2_000_000):
            s += i

    a = np.empty(32 << 20)  # (256 MiB, its pages touched once before the timing)
    a.fill(0.0)
    data = bytes(64 << 20)
    py = 2.0 / best(loop)
    mem = a.nbytes / 1e9 / best(lambda: a.fill(1.0))
    sha = len(data) / 1e6 / best(lambda: hashlib.sha256(data).digest())
    return f"machine gauge: CPython loop {py:.1f} M/s, NumPy write {mem:.1f} GB/s, SHA-256 {sha:.0f} MB/s"


if __name__ == "__main__":
    print(machine_gauge())
