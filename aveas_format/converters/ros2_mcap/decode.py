"""Opening and decoding the MCAP files: the topics and message types of a file (``channels``),
and the CDR decoders (``Decoders``: rosbags' generated deserialisers, mcap-ros2-support's generic
decoder for definitions rosbags does not parse)."""

from __future__ import annotations

import re
import struct
from pathlib import Path
from typing import Any

from aveas_format.converters.common.fastpath import FastPathUnsupported, log, read_by
from aveas_format.converters.common.mcap import mcap_errors, why
from aveas_format.converters.ros2_mcap.options import canonical_type
from aveas_format.errors import FormatError


def channels(path: Path) -> dict[str, str]:
    """topic -> canonical message type of an MCAP file (from its summary, else a scan)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None:
                return {ch.topic: canonical_type(summary.schemas[ch.schema_id].name)
                        for ch in summary.channels.values() if ch.schema_id in summary.schemas}
            out = {}
            for schema, ch, _ in reader.iter_messages(log_time_order=False):
                if schema is not None:
                    out.setdefault(ch.topic, canonical_type(schema.name))
            return out
    except mcap_errors() as e:
        raise FormatError(f"not a readable MCAP file: {why(e)}", path=path) from None


class DecoderError(Exception):
    """No decoder reads a schema (its encoding, or a definition mcap-ros2-support's parser
    refuses): ``str`` is the reason."""


def decode_errors() -> tuple[type[BaseException], ...]:
    """What the decoders raise on message bytes that do not decode as their schema says:
    rosbags' SerdeError (which wraps its deserialisers' errors) and TypesysError (a type of the
    definition it cannot deserialise), mcap-ros2-support's CDR reader's ValueError and
    RuntimeError (NotImplementedError for types it does not read), and the struct/index errors
    of truncated bytes."""
    from rosbags.serde import SerdeError
    from rosbags.typesys.base import TypesysError

    return (ValueError, struct.error, IndexError, EOFError, OverflowError, RuntimeError,
            SerdeError, TypesysError)


class Decoders:
    """CDR decoding, one decoder per schema: rosbags' deserialisers, generated for each message
    type (3-4x faster than mcap_ros2's generic decoder on TrackedObjects), and mcap_ros2's decoder
    for schemas rosbags does not parse (e.g. ``ros2idl``; which one decodes a schema is logged,
    ``--verbose``). One type store per schema, so two files with different definitions of one
    type name do not clash."""

    def __init__(self) -> None:
        from mcap_ros2.decoder import DecoderFactory

        self._generic = DecoderFactory()
        self._by_schema: dict[tuple[int, str], Any] = {}

    def decoder(self, schema, encoding: str, path: Path):
        key = (schema.id, schema.name)
        fn = self._by_schema.get(key)
        if fn is None:
            fn = self._by_schema[key] = self._make(schema, encoding, path)
        return fn

    def _make(self, schema, encoding: str, path: Path):
        if encoding != "cdr":
            raise DecoderError(f"ValueError: unsupported message encoding {encoding!r}")
        what = f"{path.name}: messages of {schema.name}"
        if schema.encoding != "ros2msg":
            log.info("%s: decoded by mcap-ros2-support (schema encoding %s)", what, schema.encoding)
            return self._generic_decoder(schema, encoding, path)
        return read_by(what, ("rosbags", lambda: self._rosbags(schema)),
                       ("mcap-ros2-support", lambda: self._generic_decoder(schema, encoding, path)))

    def _generic_decoder(self, schema, encoding: str, path: Path):
        """mcap-ros2-support's decoder; :class:`DecoderError` where its parser refuses the
        definition (ValueError, TypeError, NotImplementedError, McapError)."""
        from mcap.exceptions import McapError

        try:
            decode = self._generic.decoder_for(encoding, schema)
        except (ValueError, TypeError, NotImplementedError, McapError) as e:
            raise DecoderError(f"{type(e).__name__}: {e}") from None
        if decode is None:
            raise DecoderError(f"ValueError: unsupported schema encoding {schema.encoding!r}")
        return decode

    @staticmethod
    def _rosbags(schema):
        """rosbags' deserialiser of the schema; :class:`FastPathUnsupported` where rosbags does
        not parse its definition."""
        from rosbags.typesys import Stores, get_typestore, get_types_from_msg
        from rosbags.typesys.base import TypesysError

        text = schema.data.decode("utf-8", "replace")
        parts = re.split(r"^={10,}\s*$\n?", text, flags=re.MULTILINE)
        try:
            types = dict(get_types_from_msg(parts[0], schema.name))
            for part in parts[1:]:
                head, _, body = part.strip("\n").partition("\n")
                if not head.startswith("MSG:"):
                    raise FastPathUnsupported(f"schema part without a MSG: header: {head[:60]!r}")
                types.update(get_types_from_msg(body, head[4:].strip()))
            store = get_typestore(Stores.EMPTY)
            store.register(types)
        except TypesysError as e:
            raise FastPathUnsupported(f"rosbags cannot parse the definition: {e}") from None
        name = schema.name
        return lambda data: store.deserialize_cdr(data, name)
