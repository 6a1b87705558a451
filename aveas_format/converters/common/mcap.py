"""What a corrupt MCAP file raises from the ``mcap`` reader, for the importers that read MCAP
(ROS 2, OSI): one tuple to catch and one line to say."""

from __future__ import annotations

import struct


def mcap_errors() -> tuple[type[BaseException], ...]:
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


def why(e: BaseException) -> str:
    """One line for an error of the MCAP reader (a bare MemoryError explained)."""
    if isinstance(e, MemoryError) and not str(e):
        return "MemoryError: a record's length field is implausibly large"
    return f"{type(e).__name__}: {e}"
