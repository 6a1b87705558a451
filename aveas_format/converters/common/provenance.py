"""Where a recording came from: the SHA-256 of its input files (computed in the background while a
converter reads a large input) and the ``source`` block of recording.json."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from aveas_format._version import __version__


def _sha256(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    buf = bytearray(chunk)  # (one buffer read into again and again: no fresh pages per read)
    view = memoryview(buf)
    with open(path, "rb", buffering=0) as f:
        while n := f.readinto(buf):
            h.update(view[:n])
    return h.hexdigest()


#: digests being computed by :func:`prefetch_sha256`, by (path, size, mtime)
_PENDING: dict[tuple, Any] = {}


def _file_key(path: Path) -> tuple | None:
    try:
        st = Path(path).stat()
    except OSError:
        return None
    return (str(Path(path).resolve()), st.st_size, st.st_mtime_ns)


def prefetch_sha256(path: Path) -> None:
    """Start hashing ``path`` in a thread (hashlib releases the GIL on large blocks), for a later
    :func:`file_sha256` of the same unchanged file: a converter calls it before reading a large
    input, so that the digest is not a serial step after the reading."""
    key = _file_key(path)
    if key is None or key in _PENDING:
        return
    from aveas_format.parallel import background

    _PENDING[key] = background(_sha256, Path(path), name="sha256")


def file_sha256(path: Path, chunk: int = 1 << 22) -> str:
    """The SHA-256 of the file ``path`` (hex; the one :func:`prefetch_sha256` started where the file
    is unchanged since)."""
    fut = _PENDING.pop(_file_key(path), None)
    if fut is not None:
        try:
            return fut.result()
        except OSError:
            pass
    return _sha256(path, chunk)


def source_block(converter: str, inputs: Iterable[Path], options: Any, version: str = "1",
                 resolved: dict[str, Any] | None = None) -> dict[str, Any]:
    """The recording.json ``source`` object: converter, versions, input names + SHA-256, options.
    ``resolved``: what the converter decided where an option left it open (``auto``: the unit
    it inferred, the reconstruction it applied), recorded over the options' values."""
    opts = options.model_dump(mode="json") if hasattr(options, "model_dump") else dict(options or {})
    opts.update(resolved or {})
    return {
        "converter": converter,
        "converter_version": f"{version} (aveas-format {__version__})",
        "inputs": [{"file": Path(p).name, "sha256": file_sha256(Path(p))} for p in inputs],
        "options": opts,
    }
