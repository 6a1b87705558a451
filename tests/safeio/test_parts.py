"""One file's chunks encoded in parts by forked processes (safeio/parts.py): the same bytes as in
one process whatever the processes and the parts, the processes' states merged, no part file
left; a process that fails at once, after a part or half-way through one has its parts encoded
here instead, what was copied of them cut off the output again. (The OpenLABEL export's frames
through it: tests/converters/test_openlabel_streaming.py.)"""

from __future__ import annotations

import os
import threading
import time

import pytest

from aveas_format.safeio import atomic, parts
from aveas_format.safeio.atomic import write_chunks_atomic
from aveas_format.safeio.parts import ForkedParts, deal_parts

BOUNDS = list(range(0, 3_001, 10))  # 300 chunks of 10 rows


def _encode(part: tuple[int, int]):
    """Chunk c's bytes: the same alone as in the whole sequence."""
    for c in range(*part):
        yield b"%d:%s;" % (c, b"x" * (c % 97))


class _Count:
    """A state accumulated while encoding (in whichever process encodes), merged at the end."""

    def __init__(self) -> None:
        self.n = 0

    def encode(self, part: tuple[int, int]):
        for data in _encode(part):
            self.n += 1
            yield data


def _write(path, workers: int, count: _Count | None = None):
    count = count or _Count()
    fp = ForkedParts(count.encode, BOUNDS, workers, path.parent, state=lambda: count.n,
                     merge=lambda n: setattr(count, "n", count.n + n), prefix=".test-parts.")
    try:
        return write_chunks_atomic(path, fp.chunks()).read_bytes()
    finally:
        fp.close()


@pytest.fixture
def small_parts(monkeypatch):
    monkeypatch.setattr(parts, "PARTS_MIN_ROWS", 0)
    monkeypatch.setattr(parts, "PART_ROWS", 100)  # (many parts each)


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_the_parts_give_the_same_file_and_merge_the_states(tmp_path, small_parts, workers):
    one = b"".join(_encode((0, len(BOUNDS) - 1)))
    count = _Count()
    assert _write(tmp_path / "out.bin", workers, count) == one
    assert count.n == len(BOUNDS) - 1  # (every chunk counted once, here or in a forked process)
    assert [p.name for p in tmp_path.iterdir()] == ["out.bin"]


def test_few_rows_are_encoded_here(tmp_path, monkeypatch):
    fp = ForkedParts(_encode, BOUNDS, 3, tmp_path)  # (3,000 rows < PARTS_MIN_ROWS)
    assert fp.parts == [(0, 300, 0)] and not fp.procs
    assert b"".join(fp.chunks()) == b"".join(_encode((0, 300)))


def test_a_failing_process_has_its_parts_encoded_here(tmp_path, small_parts, monkeypatch):
    one = b"".join(_encode((0, len(BOUNDS) - 1)))
    real = parts._write_parts
    for i, fails in enumerate([lambda *a: os._exit(3),  # (at once)
                               lambda enc, st, ps, conn: real(enc, st, ps[:1], conn) or os._exit(3)]):
        monkeypatch.setattr(parts, "_write_parts", fails)
        assert _write(tmp_path / f"out{i}.bin", 2) == one
        assert sorted(p.name for p in tmp_path.iterdir()) == [f"out{k}.bin" for k in range(i + 1)]


def test_a_part_whose_process_dies_half_way_is_cut_off_and_encoded_here(tmp_path, small_parts,
                                                                         monkeypatch):
    one = b"".join(_encode((0, len(BOUNDS) - 1)))
    copying = threading.Event()  # (the writer has copied some of the part before it dies)
    real_copy = atomic._copy_range
    monkeypatch.setattr(atomic, "_copy_range", lambda *a: (real_copy(*a), copying.set()))
    real = parts._write_parts

    def dies_half_way(encode, state, ps, conn):
        real(encode, state, ps[:1], conn)  # (one whole part)
        _, part, spill = ps[1]
        with open(spill, "wb") as f:
            f.write(next(iter(encode(part=part))))
            f.flush()
        time.sleep(0.5)  # (time for the writer to copy what is there)
        os._exit(3)

    monkeypatch.setattr(parts, "_write_parts", dies_half_way)
    assert _write(tmp_path / "out.bin", 2) == one
    assert copying.is_set() and [p.name for p in tmp_path.iterdir()] == ["out.bin"]


def test_the_parts_are_dealt_in_rounds_of_about_equal_rows():
    bounds = list(range(0, 2_000_001, 10_000))  # 200 chunks of 10,000 rows
    dealt = deal_parts(bounds, 2)
    assert [o for _, _, o in dealt] == [0, 1] * 5 + [0]  # 2M / (200k x 2) rounds, the last part here
    assert dealt[0][0] == 0 and dealt[-1][1] == 200
    assert all(a[1] == b[0] for a, b in zip(dealt, dealt[1:]))  # contiguous, every chunk once
    rows = [bounds[b] - bounds[a] for a, b, _ in dealt]
    assert max(rows) - min(rows) <= 10_000  # about equal: a chunk at most
    dealt3 = deal_parts(bounds, 3)
    assert [o for _, _, o in dealt3][:6] == [0, 1, 2, 0, 1, 2] and dealt3[-1][2] == 0
    assert deal_parts(bounds[:4], 2) == [(0, 3, 0)]  # too few chunks to share
    assert deal_parts(bounds, 1) == [(0, 200, 0)]
    assert [o for _, _, o in deal_parts(bounds[:21], 2)] == [0, 1, 0]  # 200k rows: one round
