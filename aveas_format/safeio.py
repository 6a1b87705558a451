"""Hardened readers for untrusted input: one XML parser factory, bounded JSON, ZIP member checks.

Recordings and source files arrive from many partners and ``validate`` runs on submissions nobody
has looked at yet (docs/security.md). Every reader of the package parses XML through
:func:`xml_parser` / :func:`iterparse` (no DTD loading, no external entities, no network, libxml2's
default limits against entity-expansion bombs and huge trees), JSON through :func:`load_json`
(size and nesting limits) and ZIP archives through :func:`check_zip_member` (no absolute or ``..``
names, bounded decompressed size and ratio).
"""

from __future__ import annotations

import json
import zipfile
from pathlib import PurePosixPath
from typing import IO, Any

from lxml import etree

from aveas_format.errors import FormatError, RecordingIOError

#: recording.json and other metadata files
MAX_JSON_BYTES = 64 * 1024 * 1024
#: OpenLABEL and other bulk JSON inputs
MAX_BULK_JSON_BYTES = 4 * 1024 * 1024 * 1024
MAX_JSON_DEPTH = 64
#: a compressed ZIP member is decompressed into memory: at most this many bytes ...
MAX_ZIP_MEMBER_BYTES = 8 * 1024 * 1024 * 1024
#: ... and at most this ratio of decompressed to compressed size (zip bombs reach 1000:1 and more)
MAX_ZIP_RATIO = 200


def xml_parser(*, remove_comments: bool = True, **kw: Any) -> etree.XMLParser:
    """An lxml parser that never loads a DTD, resolves no entity, touches no network and keeps
    libxml2's limits (no ``huge_tree``): external-entity and entity-expansion attacks fail."""
    return etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False,
                           dtd_validation=False, huge_tree=False, remove_comments=remove_comments,
                           remove_pis=True, **kw)


def iterparse(source: str | IO[bytes], **kw: Any) -> etree.iterparse:
    """``lxml.etree.iterparse`` with the protections of :func:`xml_parser`."""
    kw.setdefault("remove_comments", True)
    return etree.iterparse(source, resolve_entities=False, no_network=True, load_dtd=False,
                           dtd_validation=False, huge_tree=False, remove_pis=True, **kw)


def _depth_ok(obj: Any, limit: int) -> bool:
    stack = [(obj, 1)]
    while stack:
        o, d = stack.pop()
        if d > limit:
            return False
        if isinstance(o, dict):
            stack.extend((v, d + 1) for v in o.values())
        elif isinstance(o, list):
            stack.extend((v, d + 1) for v in o)
    return True


def load_json(data: bytes | str, *, path: object = None, max_bytes: int = MAX_JSON_BYTES,
              max_depth: int = MAX_JSON_DEPTH) -> Any:
    """Parse JSON with a size and a nesting limit; errors name the file and line/column."""
    size = len(data)
    if size > max_bytes:
        raise FormatError(f"JSON of {size:,} bytes exceeds the limit of {max_bytes:,}", path=path)
    try:
        obj = json.loads(data)
    except UnicodeDecodeError:
        raise FormatError("not UTF-8 text", path=path) from None
    except json.JSONDecodeError as e:
        raise FormatError(f"broken JSON: {e.msg}", path=path, line=e.lineno, column=e.colno) from None
    except RecursionError:
        raise FormatError(f"JSON nested deeper than {max_depth} levels", path=path) from None
    if not _depth_ok(obj, max_depth):
        raise FormatError(f"JSON nested deeper than {max_depth} levels", path=path)
    return obj


def check_zip_member(info: zipfile.ZipInfo, archive: object) -> None:
    """Refuse a member with an absolute or parent-relative name, or one that decompresses to more
    than :data:`MAX_ZIP_MEMBER_BYTES` or at a ratio above :data:`MAX_ZIP_RATIO`."""
    name = info.filename
    p = PurePosixPath(name.replace("\\", "/"))
    if p.is_absolute() or ".." in p.parts or (len(name) > 1 and name[1] == ":"):
        raise RecordingIOError(f"ZIP member {name!r} has an unsafe path; refused", path=archive)
    if info.compress_type != zipfile.ZIP_STORED:
        if info.file_size > MAX_ZIP_MEMBER_BYTES:
            raise RecordingIOError(f"ZIP member {name!r} decompresses to {info.file_size:,} bytes "
                                   f"(limit {MAX_ZIP_MEMBER_BYTES:,}); refused", path=archive)
        if info.file_size > 1024 * 1024 and info.file_size > MAX_ZIP_RATIO * max(info.compress_size, 1):
            raise RecordingIOError(f"ZIP member {name!r} has a compression ratio above "
                                   f"{MAX_ZIP_RATIO}:1 (a zip bomb?); refused", path=archive)
