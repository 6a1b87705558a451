"""Opening and decoding the MCAP files: what a corrupt file raises, the topics and message types
of a file (``_channels``), and the CDR decoders (``_Decoders``: rosbags' generated deserialisers,
mcap-ros2-support's generic decoder as the fallback)."""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Any

from aveas_format.converters.ros2_mcap.options import _canon
from aveas_format.errors import FormatError


def _mcap_errors() -> tuple[type[BaseException], ...]:
    """What a corrupt MCAP file raises from the reader: record-level errors, a damaged record
    length (OverflowError) and, from a damaged compressed chunk, the decompressors' own
    (zstandard.ZstdError; lz4 raises RuntimeError). Lengths beyond the file and oversized chunks
    are refused before the reader runs (``safeio.check_mcap``); MemoryError stays listed only as a
    last resort."""
    from mcap.exceptions import McapError

    errs: list[type[BaseException]] = [McapError, ValueError, EOFError, KeyError, OSError,
                                       struct.error, IndexError, RuntimeError, OverflowError,
                                       MemoryError]
    try:
        import zstandard

        errs.append(zstandard.ZstdError)
    except ImportError:  # pragma: no cover - mcap depends on it
        pass
    return tuple(errs)


def _why(e: BaseException) -> str:
    """One line for an error of the MCAP reader (a bare MemoryError explained)."""
    if isinstance(e, MemoryError) and not str(e):
        return "MemoryError: a record's length field is implausibly large"
    return f"{type(e).__name__}: {e}"


def _channels(path: Path) -> dict[str, str]:
    """topic -> canonical message type of an MCAP file (from its summary, else a scan)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None:
                return {ch.topic: _canon(summary.schemas[ch.schema_id].name)
                        for ch in summary.channels.values() if ch.schema_id in summary.schemas}
            out = {}
            for schema, ch, _ in reader.iter_messages(log_time_order=False):
                if schema is not None:
                    out.setdefault(ch.topic, _canon(schema.name))
            return out
    except _mcap_errors() as e:
        raise FormatError(f"not a readable MCAP file: {_why(e)}", path=path) from None


class _Decoders:
    """CDR decoding, one decoder per schema: rosbags' deserialisers, generated for each message
    type (3-4x faster than mcap_ros2's generic decoder on TrackedObjects), and mcap_ros2's decoder
    for schemas rosbags does not parse (e.g. ``ros2idl``). One type store per schema, so two files
    with different definitions of one type name do not clash."""

    def __init__(self) -> None:
        from mcap_ros2.decoder import DecoderFactory

        self._fallback = DecoderFactory()
        self._by_schema: dict[tuple[int, str], Any] = {}

    def decoder(self, schema, encoding: str):
        key = (schema.id, schema.name)
        fn = self._by_schema.get(key)
        if fn is None:
            fn = self._by_schema[key] = self._make(schema, encoding)
        return fn

    def _make(self, schema, encoding: str):
        if encoding != "cdr":
            raise ValueError(f"unsupported message encoding {encoding!r}")
        if schema.encoding == "ros2msg":
            try:
                return self._rosbags(schema)
            except Exception:  # noqa: BLE001 - rosbags cannot parse it: the generic decoder tries
                pass
        decode = self._fallback.decoder_for(encoding, schema)
        if decode is None:
            raise ValueError(f"unsupported schema encoding {schema.encoding!r}")
        return decode

    @staticmethod
    def _rosbags(schema):
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg

        text = schema.data.decode("utf-8")
        parts = re.split(r"^={10,}\s*$\n?", text, flags=re.MULTILINE)
        types = dict(get_types_from_msg(parts[0], schema.name))
        for part in parts[1:]:
            head, _, body = part.strip("\n").partition("\n")
            if not head.startswith("MSG:"):
                raise ValueError(f"schema part without a MSG: header: {head[:60]!r}")
            types.update(get_types_from_msg(body, head[4:].strip()))
        store = get_typestore(Stores.EMPTY)
        store.register(types)
        name = schema.name
        return lambda data: store.deserialize_cdr(data, name)
