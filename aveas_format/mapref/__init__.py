"""Map-referencing: the layer above ``opendrive`` and ``io`` that ties positions to the map.

- :mod:`~aveas_format.mapref.crs`: the recording's CRS, local frame <-> WGS 84 (pyproj), lenient
  reading of malformed ``<geoReference>`` strings;
- :mod:`~aveas_format.mapref.roads`: OpenDRIVE road coordinates of a states table;
- :mod:`~aveas_format.mapref.build`: :func:`build_recording`, a valid recording from plain arrays
  (fills heading/velocity, lon/lat and road coordinates).
"""

from aveas_format.mapref.build import build_recording, load_map_bytes
from aveas_format.mapref.crs import GeoReferenceWarning, LocalFrame, crs_equal, parse_crs
from aveas_format.mapref.roads import road_coordinates

__all__ = ["GeoReferenceWarning", "LocalFrame", "build_recording", "crs_equal", "load_map_bytes",
           "parse_crs", "road_coordinates"]
