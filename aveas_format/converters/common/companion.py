"""What an exporter writes next to its output so that the export re-imports: the map, with the
recording's CRS as its ``<geoReference>`` where the map has none.

Two exports of one recording next to each other (``-o hw.json`` and ``-o hw.xosc``) name the same
map (``hw.xodr``): every exporter writes the same bytes for it (:func:`companion_map`), and an
existing file with exactly those bytes is no conflict (:func:`is_same_companion`): it is kept as
it is (:func:`write_companion_map`). A different file of that name is replaced only with
``--overwrite``."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any


def companion_map_path(output: Path, options: Any) -> Path | None:
    """Where an exporter writes the map next to its ``output``: the option ``map_file`` or the
    output's name with ``.xodr``; None where the exporter has no map or ``write_map`` is off. The
    one rule of every exporter that writes a map (the ``export`` command refuses to replace it
    without ``--overwrite``)."""
    if not getattr(options, "write_map", False):
        return None
    output = Path(output)
    return output.parent / (getattr(options, "map_file", None) or f"{output.stem}.xodr")


def companion_map(rec) -> bytes | None:
    """The map to write next to an export: the recording's map, with the recording's ``crs`` as its
    ``<geoReference>`` where the map has none, so that the export's re-import finds the frame
    (FORMAT.md: without a geoReference, ``crs`` alone defines it; the OpenSCENARIO and OSI re-imports
    read it from this map). The rest of the map's bytes are unchanged."""
    data = rec.map_source
    if data is None:
        return None
    crs = rec.meta.crs
    if not crs or rec.map.header.geo_reference:
        return data
    head = re.search(rb"<header\b[^>]*?(/?)>", data)
    if head is None:
        return data
    geo = b"<geoReference><![CDATA[" + crs.replace("]]>", "").encode() + b"]]></geoReference>"
    if head.group(1):  # <header .../>
        new = head.group(0)[:-2].rstrip() + b">" + geo + b"</header>"
    else:
        new = head.group(0) + geo
    return data[:head.start()] + new + data[head.end():]


def is_same_companion(rec, path: Path) -> bool:
    """Whether ``path`` is a file with exactly the bytes of ``rec``'s companion map (another
    export of the same recording wrote it): no conflict, nothing to write."""
    path = Path(path)
    data = companion_map(rec)
    return data is not None and path.is_file() and path.stat().st_size == len(data) \
        and path.read_bytes() == data


def write_companion_map(rec, path: Path) -> Path:
    """Write ``rec``'s companion map to ``path`` (atomically), unless the file there has exactly
    its bytes already (kept as it is); ``path`` either way."""
    from aveas_format.safeio import write_bytes_atomic

    if is_same_companion(rec, path):
        return Path(path)
    return write_bytes_atomic(Path(path), companion_map(rec))
