"""Map-referencing: the layer above ``opendrive`` and ``io`` that ties positions to the map.

- :mod:`~aveas_format.mapref.roads`: OpenDRIVE road coordinates of a states table;
- :mod:`~aveas_format.mapref.build`: :func:`build_recording`, a valid recording from plain arrays
  (fills heading/velocity, lon/lat and road coordinates).

The recording's CRS and its local frame (local <-> projected <-> WGS 84) are read by
:mod:`aveas_format.crs`, below ``io``, which uses it for ``Recording.to_geopandas``.
"""

from aveas_format.mapref.build import build_recording, load_map_bytes
from aveas_format.mapref.roads import road_coordinates

__all__ = ["build_recording", "load_map_bytes", "road_coordinates"]
