"""Fit an OpenDRIVE road to annotated polylines (lane centres or lane borders / markings).

For maps annotated on an orthophoto, and for converters whose sources give lanes as polylines
(accident reconstructions, highD's lane markings)::

    from aveas_format.opendrive.roadfit import fit_road, road_from_lane_markings

    fit = road_from_lane_markings([m0, m1, m2, m3], driving="right")   # (N, 2) arrays, left to right
    fit.xodr                      # OpenDRIVE 1.8 text (XSD-valid)
    fit.network()                 # the RoadNetwork (load_map of the text)
    fit.rms, fit.max_error        # reference line vs. the polyline it was fitted to [m]

    fit = fit_road([c0, c1, c2], kind="centres", driving="both", left_lanes=1)

(Named ``roadfit`` to keep it apart from :mod:`aveas_format.fit`, the behaviour-parameter
fitter.) What lives where, from the bottom up; each module's docstring describes its part of the
method:

- ``checks``: the input checks (``as_line``, ``check_simple``): malformed polylines raise
  :class:`~aveas_format.errors.MapError` (a ValueError) naming the line and where.
- ``spline``: the clothoid spline (curvature piecewise linear in s) and its Levenberg-Marquardt
  least-squares problems (``Spline``, ``Problem``, ``KnotProblem``).
- ``reference``: the reference line, a G2 line/arc/spiral chain fitted to one polyline
  (:func:`fit_reference_line`, :class:`ReferenceFit`: start values, knot refinement, snapping to
  lines and arcs, the exact chained geometries).
- ``road``: the road (:func:`fit_road`, :func:`road_from_lane_markings`, :class:`RoadFit`): the
  lines projected onto the reference line, their P-splines of t(s), the lane borders, widths and
  lane offset as exact piecewise cubics in one lane section.
"""

from aveas_format.opendrive.roadfit.reference import ReferenceFit, fit_reference_line
from aveas_format.opendrive.roadfit.road import RoadFit, fit_road, road_from_lane_markings

__all__ = ["ReferenceFit", "RoadFit", "fit_reference_line", "fit_road", "road_from_lane_markings"]
