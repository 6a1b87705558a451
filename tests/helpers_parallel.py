"""Module-level task functions for tests/parallel/test_parallel.py (picklable by worker processes)."""

from __future__ import annotations

import os


def square(x: int) -> int:
    return x * x


def fail_on_three(x: int) -> int:
    if x == 3:
        raise ValueError("three is not allowed")
    return x


def crash_on_two(x: int) -> int:
    if x == 2:
        os._exit(13)  # the worker process dies without a Python exception
    return x + 100
