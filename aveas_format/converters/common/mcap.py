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


def viewing_export_note(path) -> str | None:
    """Where an MCAP file holds only Foxglove viewing messages (``foxglove.*`` schemas: this
    toolkit's ``export --to mcap``, a viewer's own recording), one line that says so, naming
    the recording it was exported from where its metadata does; else None. Such a file is for
    looking at, not for exchange: no importer reads it back."""
    from pathlib import Path

    from mcap.reader import make_reader

    from aveas_format.safeio import check_mcap

    path = Path(path)
    try:
        check_mcap(path)
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            schemas = sorted({s.name for s in summary.schemas.values()}) if summary else []
            if not schemas or not all(n.startswith("foxglove.") for n in schemas):
                return None
            rec_id = next((m.metadata.get("recording_id") for m in reader.iter_metadata()
                           if m.name == "aveas" and m.metadata.get("recording_id")), None)
    except mcap_errors():
        return None
    of = f" of recording {rec_id!r}" if rec_id else ""
    return (f"a Foxglove MCAP for viewing{of} ({', '.join(schemas)}; `aveas-format export --to "
            "mcap` writes such files): no importer reads it back; import the recording it was "
            "exported from, or exchange it as OSI, OpenLABEL or OpenSCENARIO (`aveas-format "
            "export --to osi|openlabel|openscenario`)")
