"""Streamed atomic writes with the writing in a thread (safeio/atomic.py, issue 22): the chunks
land in order, syncs happen along the way, and an error on either side leaves nothing behind."""

from __future__ import annotations

import os

import pytest

from aveas_format.safeio import atomic
from aveas_format.safeio.atomic import write_chunks_atomic


def _chunks(n: int, size: int):
    for i in range(n):
        yield bytes([i % 251]) * size


def test_chunks_land_in_order_with_syncs_along_the_way(tmp_path, monkeypatch):
    synced = []
    real = os.fdatasync
    monkeypatch.setattr(atomic, "SYNC_EVERY", 10_000)
    monkeypatch.setattr(os, "fdatasync", lambda fd: (synced.append(fd), real(fd))[1])
    p = write_chunks_atomic(tmp_path / "out.bin", _chunks(200, 997))
    assert p.read_bytes() == b"".join(_chunks(200, 997))
    assert len(synced) == 200 // -(-10_000 // 997)  # (every 11 chunks of 997 bytes)
    assert write_chunks_atomic(tmp_path / "empty.bin", iter(())).read_bytes() == b""


def test_an_error_of_the_producer_leaves_nothing(tmp_path):
    def broken():
        yield b"x" * 1000
        raise ValueError("bad row 7")

    with pytest.raises(ValueError, match="bad row 7"):
        write_chunks_atomic(tmp_path / "out.bin", broken())
    assert list(tmp_path.iterdir()) == []


def test_an_error_of_the_writer_stops_the_producer_and_leaves_nothing(tmp_path, monkeypatch):
    made = []

    def many():
        for i in range(10_000):
            made.append(i)
            yield b"y" * 100

    class Full:  # the disk is full after the first chunk
        def __init__(self, f):
            self.f, self.n = f, 0

        def write(self, data):
            self.n += 1
            if self.n > 1:
                raise OSError(28, "No space left on device")
            return self.f.write(data)

    real = atomic._write_behind
    monkeypatch.setattr(atomic, "_write_behind", lambda f, chunks: real(Full(f), chunks))
    with pytest.raises(OSError, match="No space left"):
        write_chunks_atomic(tmp_path / "out.bin", many())
    assert list(tmp_path.iterdir()) == [] and len(made) < 10_000


def test_file_segments_are_copied_in_place_and_removed(tmp_path):
    from aveas_format.safeio.atomic import FileSegment

    parts = []
    for i in range(3):
        p = tmp_path / f"part{i}"
        p.write_bytes(bytes([65 + i]) * (100_000 + i))
        parts.append(p)
    chunks = [b"head", FileSegment(parts[0]), b"mid", FileSegment(parts[1]), FileSegment(parts[2]), b"tail"]
    out = write_chunks_atomic(tmp_path / "out.bin", iter(chunks))
    want = b"head" + b"A" * 100_000 + b"mid" + b"B" * 100_001 + b"C" * 100_002 + b"tail"
    assert out.read_bytes() == want
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


def test_file_segments_not_written_are_removed_on_an_error(tmp_path, monkeypatch):
    from aveas_format.safeio.atomic import FileSegment

    seg = tmp_path / "part"
    seg.write_bytes(b"x" * 1000)

    def chunks():
        yield b"head"
        yield FileSegment(seg)
        yield b"more"

    monkeypatch.setattr(FileSegment, "copy_into", lambda self, f, wrote: (_ for _ in ()).throw(OSError(28, "full")))
    with pytest.raises(OSError, match="full"):
        write_chunks_atomic(tmp_path / "out.bin", chunks())
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("ok", [True, False])
def test_a_growing_segment_is_copied_as_it_grows_or_cut_off_again(tmp_path, monkeypatch, ok):
    """A part file another process still appends to: copied piece by piece before it is done;
    when that process fails, what was copied of it is cut off and the next chunks land where
    the part began."""
    import threading
    import time

    from aveas_format.safeio.atomic import GrowingSegment

    part = tmp_path / "part"
    part.write_bytes(b"")
    steps = []
    real = atomic._copy_range
    monkeypatch.setattr(atomic, "_copy_range", lambda *a: (steps.append(a[3]), real(*a)))
    seg = GrowingSegment(part)

    def append() -> None:
        with open(part, "ab") as f:
            for i in range(20):
                f.write(bytes([97 + i]) * 1000)
                f.flush()
                for _ in range(500):  # (the first piece copied before the next comes)
                    if steps:
                        break
                    time.sleep(0.01)
        seg.finish(ok)

    def chunks():
        yield b"head"
        threading.Thread(target=append).start()
        yield seg
        yield b"tail"

    out = write_chunks_atomic(tmp_path / "out.bin", chunks())
    whole = b"".join(bytes([97 + i]) * 1000 for i in range(20))
    assert out.read_bytes() == b"head" + (whole if ok else b"") + b"tail"
    assert len(steps) >= (2 if ok else 1) and sum(steps) <= 20_000  # (in pieces, each byte once)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]
