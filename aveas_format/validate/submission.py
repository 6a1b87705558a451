"""A submitted file of any importable format, imported to be validated as a recording.

``aveas_format.validate("submission.json")`` (:func:`aveas_format.validate.runner.validate`) and
``aveas-format validate submission.json`` take a foreign file the same way, through these
functions:

1. the importer: ``converter`` (``--from``), else the one the registry names for the file
   (:func:`aveas_format.converters.registry.importers_for`: its file patterns, and where several
   importers share them, their ``sniff`` of the first bytes; partner converters included);
2. the import, with :func:`aveas_format.errors.collect_source_findings` active: what it finds about
   the file (the ``source.*`` rules' findings, located in the source's own terms: file, line,
   frame, entity...) and its warnings (``source.other``, so that nothing it says is lost);
   an importer that writes the recording itself (``Converter.writes``: OpenLABEL) writes a large
   file's into a temporary directory, its states in parts, and the recording is validated from
   there, streamed; others hold the imported recording's columns, as ``convert`` holds them;
3. validation of the recording with those findings.

An unimportable file raises the importer's located error (the CLI: exit 3).
"""

from __future__ import annotations

import dataclasses
import tempfile
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from aveas_format.errors import (
    MissingCrsError,
    RecordingIOError,
    SourceFinding,
    UsageError,
    collect_source_findings,
)


def submitted_files(specs: Sequence[str | Path] | None, converter: str | None = None) -> list[Path]:
    """The files of a submission when the arguments name one: with ``converter`` every argument
    is an input of it; else one existing file that is not a recording ZIP (a recording is a
    directory or a ``.zip``). Empty where the arguments name recordings."""
    if not specs:
        return []
    if converter:
        return [Path(s) for s in specs]
    p = Path(specs[0])
    if len(specs) == 1 and p.is_file() and not p.name.lower().endswith(".zip"):
        return [p]
    return []


def importer_of(inputs: Sequence[Path], converter: str | None = None) -> str:
    """The name of the importer of a submission (``converter`` where given)."""
    from aveas_format.converters.registry import importers_for

    if converter:
        return converter
    first = Path(inputs[0])
    hits = importers_for(first)
    if len(hits) == 1:
        return hits[0]
    if first.suffix.lower() == ".mcap" and len(hits) != 1:
        from aveas_format.converters.common.mcap import viewing_export_note
        from aveas_format.errors import FormatError

        note = viewing_export_note(first)
        if note:
            raise FormatError(f"not importable: {note}", path=first)
    if hits:
        raise UsageError(f"{first}: several converters read {first.suffix or 'it'} "
                         f"({', '.join(hits)}): pass --from NAME")
    raise RecordingIOError("not a recording, and no converter reads files like it (pass --from "
                           "NAME; `aveas-format convert --list` lists them)", path=first)


def import_submission(inputs: Sequence[Path], converter: str | None = None,
                      map_source: str | Path | bytes | None = None,
                      options: dict[str, Any] | None = None, crs: str | None = None,
                      workdir: Path | None = None) -> tuple[Any, list[SourceFinding]]:
    """Import a submitted file and collect what the import finds about it: ``(recording,
    [SourceFinding])``; with ``workdir``, an importer that writes the recording itself writes it
    there (a large file's states in parts) and the recording is its path where its states were
    not loaded. Findings without a file name the (first) input; a warning of an importer that
    does not report located findings becomes a ``source.other`` finding."""
    from aveas_format.converters.registry import UnstatedWarning, convert, convert_to, get_converter
    from aveas_format.mapref.offmap import OffMapWarning

    inputs = [Path(p) for p in inputs]
    name = importer_of(inputs, converter)
    to_disk = workdir is not None and get_converter(name).writes is not None
    with collect_source_findings() as found, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", DeprecationWarning)
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        warnings.simplefilter("ignore", UnstatedWarning)  # (the metadata rules say it, located)
        warnings.simplefilter("ignore", OffMapWarning)  # (map.mostly_off_road says it)
        try:
            if to_disk:
                rec, _, _ = convert_to(name, inputs, Path(workdir) / "submission.aveas",
                                       map_source=map_source, options=options, crs=crs)
                rec = rec if rec.states is not None else rec.path
            else:
                rec = convert(name, inputs, map_source=map_source, options=options, crs=crs)
        except MissingCrsError as e:  # its message shows the convert command: show this one
            raise MissingCrsError(e.message.replace("aveas-format convert ", "aveas-format "
                                                    "validate ").replace(" -o OUT.aveas", ""),
                                  path=e.path) from None
    file = str(inputs[0])
    out = [f if "file" in f.location else
           dataclasses.replace(f, location={"file": file, **f.location}) for f in found]
    seen: set[str] = set()
    for w in caught:
        msg = str(w.message)
        if msg not in seen:
            seen.add(msg)
            out.append(SourceFinding("source.other", msg, {"file": file}))
    return rec, out


@contextmanager
def imported(inputs: Sequence[Path], converter: str | None = None,
             map_source: str | Path | bytes | None = None, options: dict[str, Any] | None = None,
             crs: str | None = None) -> Iterator[tuple[Any, list[SourceFinding]]]:
    """:func:`import_submission` into a temporary directory that lives as long as the context
    (a large file's recording is written there)."""
    with tempfile.TemporaryDirectory(prefix="aveas-validate-") as work:
        yield import_submission(inputs, converter, map_source, options, crs, Path(work))
