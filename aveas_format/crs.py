"""The recording's CRS, read leniently, and its local frame <-> projected <-> WGS 84 (pyproj,
always_xy, vectorised). In the foundation (it imports nothing of the package but ``errors``), so
that ``io`` (``Recording.to_geopandas``), map-referencing, the converters and the validator share
one reading of a CRS string.

The local frame of a recording is the OpenDRIVE inertial frame of its map. Where the map has a
``<geoReference>`` (a PROJ string) and a header ``<offset x y z hdg>``, a local point maps to the
projected CRS as (ASAM OpenDRIVE 1.6+, the same convention as OSI's ``proj_frame_offset``)::

    x_proj = x cos(hdg) - y sin(hdg) + offset_x
    y_proj = x sin(hdg) + y cos(hdg) + offset_y

Real maps carry malformed strings; :func:`parse_crs` reads them leniently, always with a warning
(never a silent guess):

- no ``+proj`` but ``+lat_0``/``+lon_0`` (CARLA): a transverse Mercator at that origin (k = 1,
  false easting/northing 0, WGS 84);
- ``+proj=utm`` without ``+zone`` (esmini): the same transverse Mercator at ``+lat_0``/``+lon_0``
  (the maps' coordinates are local, near 0, which a true UTM zone would not give);
- ``+geoidgrids``/``+vunits`` naming a grid file that PROJ cannot find: the vertical part is dropped
  (horizontal coordinates are unaffected).
"""

from __future__ import annotations

import functools
import re
import warnings
from dataclasses import dataclass, field

import numpy as np
import pyproj
from pyproj.exceptions import CRSError, ProjError

from aveas_format.errors import FormatError

WGS84 = "EPSG:4326"


class GeoReferenceWarning(UserWarning):
    """A geoReference / CRS string was read leniently; the message says how."""


@dataclass(frozen=True)
class ParsedCrs:
    """A CRS read from a string, with how it was read."""

    text: str
    crs: pyproj.CRS
    lenient: bool = False
    notes: tuple[str, ...] = field(default_factory=tuple)


_PARAM = re.compile(r"\+([A-Za-z_0-9]+)(?:=(\S*))?")


def _params(text: str) -> dict[str, str | None]:
    return {m.group(1): m.group(2) for m in _PARAM.finditer(text)}


def _tmerc_at(lat0: str | None, lon0: str | None) -> str:
    try:
        lat, lon = float(lat0 or 0), float(lon0 or 0)
    except ValueError:
        raise FormatError(f"+lat_0={lat0!r} / +lon_0={lon0!r} are not numbers") from None
    return (f"+proj=tmerc +lat_0={lat!r} +lon_0={lon!r} +k=1 +x_0=0 +y_0=0 "
            "+ellps=WGS84 +units=m +no_defs")


def _usable(crs: pyproj.CRS) -> bool:
    try:
        pyproj.Transformer.from_crs(crs, WGS84, always_xy=True).transform(0.0, 0.0, errcheck=True)
        return True
    except (ProjError, CRSError):
        return False


@functools.lru_cache(maxsize=64)
def parse_crs(text: str) -> ParsedCrs:
    """Read a PROJ/EPSG/WKT string, leniently for the known malformed cases (see module doc).

    Raises FormatError when no reading is possible.
    """
    raw = (text or "").strip()
    if raw.startswith("<![CDATA[") and raw.endswith("]]>"):
        raw = raw[9:-3].strip()
    if not raw:
        raise FormatError("empty CRS / geoReference string")
    notes: list[str] = []
    candidate = raw
    if raw.lstrip().startswith("+"):
        p = _params(raw)
        if "proj" not in p:
            if "lat_0" in p or "lon_0" in p:
                candidate = _tmerc_at(p.get("lat_0"), p.get("lon_0"))
                notes.append("no +proj: read as a transverse Mercator at +lat_0/+lon_0")
            else:
                raise FormatError(f"CRS string has neither +proj nor +lat_0/+lon_0: {raw!r}")
        elif p.get("proj") == "utm" and "zone" not in p:
            if "lat_0" in p or "lon_0" in p:
                candidate = _tmerc_at(p.get("lat_0"), p.get("lon_0"))
                notes.append("+proj=utm without +zone: read as a transverse Mercator at +lat_0/+lon_0")
            else:
                raise FormatError(f"+proj=utm without +zone and without +lon_0: {raw!r}")
    try:
        crs = pyproj.CRS.from_user_input(candidate)
    except CRSError as e:
        raise FormatError(f"unreadable CRS {raw!r}: {str(e).splitlines()[0]}") from None
    if not _usable(crs) and candidate.lstrip().startswith("+"):
        stripped = re.sub(r"\+(geoidgrids|vunits|geoid_crs)=\S*", "", candidate)
        stripped = re.sub(r"\s+", " ", stripped).strip()
        try:
            crs2 = pyproj.CRS.from_user_input(stripped)
        except CRSError:
            crs2 = None
        if crs2 is not None and _usable(crs2):
            notes.append("vertical grid not available: +geoidgrids/+vunits dropped (heights not "
                         "transformed)")
            crs = crs2
    if not _usable(crs):
        raise FormatError(f"CRS {raw!r} cannot be transformed to WGS 84 on this machine")
    return ParsedCrs(text=raw, crs=crs, lenient=bool(notes), notes=tuple(notes))


def crs_equal(a: str, b: str) -> bool:
    """Do two CRS strings describe the same CRS (after lenient reading)?"""
    try:
        ca, cb = parse_crs(a).crs, parse_crs(b).crs
    except FormatError:
        return False
    return bool(ca == cb or ca.equals(cb, ignore_axis_order=True))


@functools.lru_cache(maxsize=32)
def _transformer(crs: str, inverse: bool) -> pyproj.Transformer:
    """The transformer CRS -> WGS 84 (``inverse``: back), made once per process and CRS where it is
    first used (making one costs ~50 ms: an import and validate made six for one file; pyproj's
    transformers are thread-safe since 3.1)."""
    c = parse_crs(crs).crs
    return pyproj.Transformer.from_crs(WGS84, c, always_xy=True) if inverse else \
        pyproj.Transformer.from_crs(c, WGS84, always_xy=True)


class LocalFrame:
    """Transforms between a recording's local frame and WGS 84 (vectorised, both directions)."""

    def __init__(self, crs: str, offset: tuple[float, float, float, float] | None = None,
                 *, warn: bool = True) -> None:
        self.parsed = parse_crs(crs)
        if warn:
            for note in self.parsed.notes:
                warnings.warn(f"CRS {self.parsed.text!r}: {note}", GeoReferenceWarning, stacklevel=2)
        self.offset = offset or (0.0, 0.0, 0.0, 0.0)
        self._crs = crs

    @property
    def _fwd(self) -> pyproj.Transformer:
        return _transformer(self._crs, False)

    @property
    def _inv(self) -> pyproj.Transformer:
        return _transformer(self._crs, True)

    @classmethod
    def of(cls, rec, *, warn: bool = True) -> LocalFrame:
        """The local frame of a recording: the CRS of its recording.json with its map header's
        ``<offset>``."""
        return cls(rec.meta.crs, offset=rec.map.header.offset, warn=warn)

    def to_projected(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ox, oy, _, hdg = self.offset
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if hdg:
            c, s = np.cos(hdg), np.sin(hdg)
            x, y = x * c - y * s, x * s + y * c
        return x + ox, y + oy

    def from_projected(self, px: np.ndarray, py: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ox, oy, _, hdg = self.offset
        x = np.asarray(px, dtype=np.float64) - ox
        y = np.asarray(py, dtype=np.float64) - oy
        if hdg:
            c, s = np.cos(hdg), np.sin(hdg)
            x, y = x * c + y * s, -x * s + y * c
        return x, y

    def to_wgs84(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lon, lat) in degrees of local points."""
        px, py = self.to_projected(x, y)
        lon, lat = self._fwd.transform(px, py)
        return np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)

    def from_wgs84(self, lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local (x, y) of WGS 84 points."""
        px, py = self._inv.transform(np.asarray(lon, np.float64), np.asarray(lat, np.float64))
        return self.from_projected(np.asarray(px), np.asarray(py))
