"""Lanelet2 maps (OSM XML) read with lxml and converted to OpenDRIVE 1.8.

>>> from aveas_format.opendrive.lanelet2 import lanelet2_to_opendrive
>>> conv = lanelet2_to_opendrive("mapping_example.osm", origin=(49.0, 8.4))   # doctest: +SKIP
>>> conv.write("site.xodr"); conv.warnings                                      # doctest: +SKIP

``osm``: the OSM file and its projection; ``lanelets``: lanelets with oriented bounds, successors
and shared bounds; ``roads``: lanelets grouped into roads and junctions; ``convert``: the roads,
lanes, links, signals and objects of the OpenDRIVE map. docs/opendrive.md ("Lanelet2 maps") says
what becomes what.
"""

from aveas_format.opendrive.lanelet2.convert import Lanelet2Conversion, lanelet2_to_opendrive
from aveas_format.opendrive.lanelet2.osm import read_osm

__all__ = ["Lanelet2Conversion", "lanelet2_to_opendrive", "read_osm"]
