"""The file-safety foundation, below every other layer: hardened readers for untrusted input and
atomic writes (docs/security.md).

Recordings and source files arrive from many partners and ``validate`` runs on submissions nobody
has looked at yet. Every reader of the package parses XML through :func:`xml_parser` /
:func:`iterparse`, JSON through :func:`load_json` (or the streaming helpers), ZIP members through
:func:`check_zip_member` and MCAP files after :func:`check_mcap`; every single-file output goes
through :func:`write_bytes_atomic` and its siblings (temporary sibling, fsync, rename).

Imports nothing of the package but :mod:`aveas_format.errors` (tests/test_layers.py checks it).
"""

from aveas_format.safeio.atomic import (
    save_figure_atomic,
    write_bytes_atomic,
    write_chunks_atomic,
    write_parquet_atomic,
    write_text_atomic,
)
from aveas_format.safeio.mcap_scan import (
    MAX_MCAP_CHUNK_BYTES,
    MAX_MCAP_RATIO,
    MAX_MCAP_UNCOMPRESSED_FLOOR,
    check_mcap,
)
from aveas_format.safeio.readers import (
    MAX_BULK_JSON_BYTES,
    MAX_JSON_BYTES,
    MAX_JSON_DEPTH,
    MAX_STREAMED_JSON_BYTES,
    MAX_ZIP_MEMBER_BYTES,
    MAX_ZIP_RATIO,
    CountingReader,
    check_json_size,
    check_zip_member,
    iterparse,
    load_json,
    scan_json_member,
    stream_json_error,
    xml_parser,
    xml_source,
)

__all__ = [
    "MAX_BULK_JSON_BYTES", "MAX_JSON_BYTES", "MAX_JSON_DEPTH", "MAX_MCAP_CHUNK_BYTES", "MAX_MCAP_RATIO",
    "MAX_MCAP_UNCOMPRESSED_FLOOR", "MAX_STREAMED_JSON_BYTES", "MAX_ZIP_MEMBER_BYTES", "MAX_ZIP_RATIO",
    "CountingReader",
    "check_json_size", "check_mcap", "check_zip_member", "iterparse", "load_json",
    "save_figure_atomic", "scan_json_member", "stream_json_error", "write_bytes_atomic", "write_chunks_atomic",
    "write_parquet_atomic", "write_text_atomic", "xml_parser", "xml_source",
]
