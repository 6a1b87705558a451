"""Hostile MCAP framing is refused by the bounded pre-scan (``safeio.check_mcap``) before the mcap
library reads the file: no record, field or chunk may claim more than the file holds (issue 11)."""

from __future__ import annotations

import struct
import time
import tracemalloc

import pytest

pytest.importorskip("mcap")
import zstandard  # noqa: E402
from mcap.data_stream import RecordBuilder  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, Message, Schema  # noqa: E402
from mcap.writer import CompressionType, Writer  # noqa: E402

from aveas_format.errors import FormatError  # noqa: E402
from aveas_format.safeio import MAX_MCAP_CHUNK_BYTES, check_mcap  # noqa: E402

MAGIC = b"\x89MCAP0\r\n"
PEAK_LIMIT = 50 * 1024 * 1024


def _valid(path, n=200, payload=b"x" * 100, compression=CompressionType.ZSTD, chunk_size=4096):
    with open(path, "wb") as f:
        w = Writer(f, compression=compression, chunk_size=chunk_size)
        w.start(profile="", library="test")
        s = w.register_schema(name="demo/Msg", encoding="jsonschema", data=b"{}")
        c = w.register_channel(topic="/demo", message_encoding="json", schema_id=s,
                               metadata={"k": "v"})
        for i in range(n):
            w.add_message(c, log_time=i, data=payload, publish_time=i)
        w.add_metadata("meta", {"a": "b"})
        w.finish()
    return path


def _records(data: bytes):
    """(offset, opcode, length) of every record between the magics."""
    pos, out = 8, []
    while pos < len(data) - 8:
        op, n = struct.unpack_from("<BQ", data, pos)
        out.append((pos, op, n))
        pos += 9 + n
    return out


def _build(records, summary_start=0) -> bytes:
    """An MCAP file of the given records, a DataEnd and a Footer."""
    rb = RecordBuilder()
    for r in records:
        r.write(rb)
    DataEnd(0).write(rb)
    Footer(summary_start, 0, 0).write(rb)
    return MAGIC + rb.end() + MAGIC


def _head():
    return [Header("", "test"), Schema(1, b"{}", "jsonschema", "demo/Msg"),
            Channel(1, "/demo", "json", {}, 1)]


def _chunk_records(n=10) -> bytes:
    rb = RecordBuilder()
    for i in range(n):
        Message(1, i, b"x" * 100, i, i).write(rb)
    return rb.end()


def _patch(data: bytes, at: int, fmt: str, value: int) -> bytes:
    b = bytearray(data)
    struct.pack_into(fmt, b, at, value)
    return bytes(b)


def _refused(path, *match):
    """check_mcap refuses the file quickly, with small peak memory; returns the message."""
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(FormatError) as e:
            check_mcap(path)
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    assert time.perf_counter() - t0 < 2.0
    assert peak < PEAK_LIMIT, peak
    msg = str(e.value)
    assert msg.startswith(str(path)) and "\n" not in msg
    for m in match:
        assert m in msg, msg
    return msg


@pytest.fixture
def valid(tmp_path):
    return _valid(tmp_path / "ok.mcap")


def test_valid_file_passes_and_reads(valid):
    check_mcap(valid)
    with open(valid, "rb") as f:
        assert sum(1 for _ in make_reader(f).iter_messages()) == 200


@pytest.mark.parametrize("compression", [CompressionType.LZ4, CompressionType.NONE])
def test_valid_file_other_compressions(tmp_path, compression):
    check_mcap(_valid(tmp_path / "ok.mcap", compression=compression))


def test_valid_lz4_without_content_size(tmp_path):
    import lz4.frame

    raw = _chunk_records()
    chunk = Chunk("lz4", lz4.frame.compress(raw, store_size=False), 9, 0, 0, len(raw))
    p = tmp_path / "lz4.mcap"
    p.write_bytes(_build(_head() + [chunk]))
    check_mcap(p)


def test_huge_record_length(tmp_path, valid):
    data = valid.read_bytes()
    p = tmp_path / "huge.mcap"
    p.write_bytes(_patch(data, 9, "<Q", 2**62))  # the Header record's length
    _refused(p, "byte 8", "Header record declares 4,611,686,018,427,387,904 bytes")


@pytest.mark.parametrize("extra", [1, 9, 1000])
def test_record_length_beyond_eof(tmp_path, valid, extra):
    data = valid.read_bytes()
    p = tmp_path / "beyond.mcap"
    for at, op, n in _records(data)[:4]:
        remaining = len(data) - 8 - at - 9
        p.write_bytes(_patch(data, at + 1, "<Q", remaining + extra))
        _refused(p, f"byte {at}", "remain before the end magic")


def test_inner_field_beyond_record(tmp_path, valid):
    data = valid.read_bytes()
    at = next(a for a, op, _ in _records(data) if op == 3)  # Schema: id u16, name, encoding, data
    name_len = struct.unpack_from("<I", data, at + 9 + 2)[0]
    p = tmp_path / "field.mcap"
    p.write_bytes(_patch(data, at + 9 + 2, "<I", 0xFFFFFFFF))
    _refused(p, f"byte {at}", "Schema record: name of 4,294,967,295 bytes")
    enc_at = at + 9 + 2 + 4 + name_len
    p.write_bytes(_patch(data, enc_at, "<I", 0xFFFF0000))
    _refused(p, "Schema record", "runs past the record's end")


def test_chunk_huge_uncompressed_size(tmp_path, valid):
    data = valid.read_bytes()
    at = next(a for a, op, _ in _records(data) if op == 6)
    p = tmp_path / "chunk.mcap"
    for size in (2**62, MAX_MCAP_CHUNK_BYTES + 1):
        p.write_bytes(_patch(data, at + 9 + 16, "<Q", size))
        _refused(p, f"byte {at}", "Chunk record", f"limit {MAX_MCAP_CHUNK_BYTES:,}")


def test_chunk_frame_larger_than_declared(tmp_path, valid):
    """python-zstandard allocates a frame's declared content size whatever max_output_size says."""
    data = valid.read_bytes()
    at = next(a for a, op, _ in _records(data) if op == 6)
    p = tmp_path / "frame.mcap"
    p.write_bytes(_patch(data, at + 9 + 16, "<Q", 10))
    _refused(p, f"byte {at}", "zstd frame declares")


def test_lz4_bomb_without_content_size(tmp_path):
    import lz4.frame

    bomb = lz4.frame.compress(b"\0" * (32 * 1024 * 1024), store_size=False)
    p = tmp_path / "lz4bomb.mcap"
    p.write_bytes(_build(_head() + [Chunk("lz4", bomb, 9, 0, 0, 1000)]))
    _refused(p, "lz4 data decompresses to more than the declared 1,000 bytes")


def test_decompression_bomb_ratio(tmp_path):
    """Chunks each within the per-chunk cap, together far beyond 1000x the file size."""
    size = 100 * 1024 * 1024
    frame = zstandard.ZstdCompressor(level=19).compress(b"\0" * size)
    p = tmp_path / "ratio.mcap"
    p.write_bytes(_build(_head() + [Chunk("zstd", frame, 9, 0, 0, size)]))
    _refused(p, "more than 1000x the file size")


def test_index_pointing_elsewhere(tmp_path, valid):
    data = valid.read_bytes()
    recs = _records(data)
    at = next(a for a, op, _ in recs if op == 8)  # ChunkIndex: start, end, chunk_start_offset
    p = tmp_path / "index.mcap"
    p.write_bytes(_patch(data, at + 9 + 16, "<Q", 8))  # at the Header
    _refused(p, f"byte {at}", "ChunkIndex points at byte 8, where no Chunk record starts")
    footer = recs[-1][0]
    p.write_bytes(_patch(data, footer + 9, "<Q", recs[2][0] + 3))  # summary_start off boundary
    _refused(p, "summary_start", "no record boundary")


def test_truncated_files(tmp_path, valid):
    data = valid.read_bytes()
    p = tmp_path / "cut.mcap"
    size = len(data)
    for n in sorted({0, 5, 8, 20, 100, size // 2, size - 30, size - 8, size - 1}):
        p.write_bytes(data[:n])
        _refused(p)


def test_truncated_then_magic_appended(tmp_path, valid):
    """A cut file with magic glued on: the footer is missing or records run past the end."""
    data = valid.read_bytes()
    p = tmp_path / "glued.mcap"
    for n in (200, len(data) // 2, len(data) - 40):
        p.write_bytes(data[:n] + MAGIC)
        _refused(p)


def test_message_shorter_than_its_header(tmp_path):
    p = tmp_path / "short.mcap"
    rb = RecordBuilder()
    for r in _head():
        r.write(rb)
    rb.write(struct.pack("<BQ", 5, 4) + b"abcd")
    DataEnd(0).write(rb)
    Footer(0, 0, 0).write(rb)
    p.write_bytes(MAGIC + rb.end() + MAGIC)
    _refused(p, "22-byte header")


def test_converters_refuse_before_reading(tmp_path, valid):
    from pathlib import Path

    from aveas_format.converters import convert

    road = Path(__file__).parents[1] / "data" / "straight.xodr"

    data = valid.read_bytes()
    p = tmp_path / "scene.mcap"
    p.write_bytes(_patch(data, 9, "<Q", 2**40))
    for name in ("ros2-mcap", "osi"):
        tracemalloc.start()
        try:
            with pytest.raises(FormatError, match=r"scene\.mcap: byte 8: MCAP Header record"):
                convert(name, [p], map_source=road)
        finally:
            _, peak = tracemalloc.get_traced_memory()
            tracemalloc.stop()
        assert peak < PEAK_LIMIT


def test_prescan_is_fast(tmp_path):
    """~20 MB in 1 MiB chunks: the pre-scan reads headers only (docs/security.md has 100 MB)."""
    p = _valid(tmp_path / "big.mcap", n=20_000, payload=bytes(range(256)) * 4,
               compression=CompressionType.NONE, chunk_size=1024 * 1024)
    t0 = time.perf_counter()
    check_mcap(p)
    assert time.perf_counter() - t0 < 1.0
