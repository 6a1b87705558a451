"""Byte-level mutations for the fuzz tests (tests/security/)."""

from __future__ import annotations

from hypothesis import strategies as st


def mutate(data: bytes, ops: list[tuple[str, int, int]]) -> bytes:
    """Apply byte-level mutations: flip, delete a span, duplicate a span, truncate, insert junk."""
    b = bytearray(data)
    for op, pos, n in ops:
        if not b:
            break
        pos %= len(b)
        n = 1 + n % 64
        if op == "flip":
            b[pos] ^= 1 << (n % 8)
        elif op == "delete":
            del b[pos:pos + n]
        elif op == "dup":
            b[pos:pos] = b[pos:pos + n]
        elif op == "truncate":
            del b[pos:]
        elif op == "junk":
            b[pos:pos] = bytes((pos * 31 + i * 7) % 256 for i in range(n))
    return bytes(b)


OPS = st.lists(st.tuples(st.sampled_from(["flip", "delete", "dup", "truncate", "junk"]),
                         st.integers(0, 10**9), st.integers(0, 10**6)), min_size=1, max_size=6)
