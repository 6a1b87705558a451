"""A road fitted to roughly parallel polylines (:func:`fit_road`, :func:`road_from_lane_markings`):
the reference line (:mod:`.reference`), then the lanes.

**Lanes.** Every input point is projected onto the fitted reference line with the engine's exact
world -> road projection, giving t(s) per input line. Each line's t(s) is fitted by a penalised
least-squares cubic B-spline (knots every ``width_spacing`` m); lane borders are these splines
(``kind="borders"``) or, for lane centres, the midpoints between neighbouring centres (the
outermost borders half the neighbouring lane spacing further out; ``lane_width`` for a single
centre line). As all splines share their knots, the lane widths (differences of borders) and the
lane offset (t of the border between the directions, zero when the reference line is that
border) are exact piecewise cubics: one ``<width>`` record per lane and knot interval, one
``<laneOffset>`` record per interval, in a single lane section.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.errors import MapError
from aveas_format.opendrive.model import Lane, LaneSection, Poly3Record, Road, RoadMark, RoadType
from aveas_format.opendrive.roadfit.checks import as_line
from aveas_format.opendrive.roadfit.reference import ReferenceFit, probe_network, fit_reference_line


def _signed_offsets(ref: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """Signed distance (positive left) of pts from the polyline ref (shapely foot points)."""
    import shapely

    line = shapely.LineString(ref)
    pos = shapely.line_locate_point(line, shapely.points(pts))
    foot = shapely.get_coordinates(shapely.line_interpolate_point(line, pos))
    cum = np.r_[0.0, np.cumsum(np.hypot(*np.diff(ref, axis=0).T))]
    i = np.clip(np.searchsorted(cum, pos, side="right") - 1, 0, len(ref) - 2)
    tan = ref[i + 1] - ref[i]
    d = pts - foot
    cross = tan[:, 0] * d[:, 1] - tan[:, 1] * d[:, 0]
    return np.sign(cross) * np.hypot(d[:, 0], d[:, 1])


def _pspline(s: np.ndarray, t: np.ndarray, L: float, spacing: float, lam: float):
    """Penalised cubic B-spline of t(s) on [0, L]: (knots, coefficients)."""
    from scipy.interpolate import BSpline

    n_int = max(1, int(round(L / spacing)))
    inner = np.linspace(0.0, L, n_int + 1)
    knots = np.r_[[0.0] * 3, inner, [L] * 3]
    nc = len(knots) - 4
    B = BSpline.design_matrix(np.clip(s, 0.0, L), knots, 3).toarray()
    w = lam * np.sqrt(max(1.0, len(s) / nc))
    D2 = np.diff(np.eye(nc), 2, axis=0) * w
    D1 = np.diff(np.eye(nc), 1, axis=0) * 1e-3
    M = np.concatenate([B, D2, D1])
    c = np.linalg.lstsq(M, np.r_[t, np.zeros(len(D2) + len(D1))], rcond=None)[0]
    return knots, c


def _pieces(knots: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints and (a, b, c, d) per interval of a cubic B-spline (local power basis)."""
    from scipy.interpolate import BSpline, PPoly

    pp = PPoly.from_spline(BSpline(knots, c, 3))
    x = pp.x
    keep = np.flatnonzero(x[1:] > x[:-1])
    return x[keep], pp.c[::-1, keep].T  # rows (a, b, c, d)


#: m: how far the written records may be from the fitted splines (they join the splines' pieces
#: that differ by less, which ASAM qc-opendrive would report as redundant records)
RECORD_TOL = 2e-4


def _records(brk: np.ndarray, coef: np.ndarray, length: float) -> np.ndarray:
    """Rows (start, a, b, c, d) of the piecewise cubic with breakpoints ``brk`` and coefficients
    ``coef``, as few as stay within :data:`RECORD_TOL` of it (exact at both ends)."""
    from aveas_format.opendrive.roadfit.records import evaluate_records, interpolating_cubics

    rows = np.column_stack([brk, coef])
    s = np.unique(np.r_[np.linspace(0.0, length, max(3, int(length / 0.25) + 1)), brk, length])
    s = s[(s >= brk[0]) & (s <= length)]
    return interpolating_cubics(s, evaluate_records(rows, s), RECORD_TOL)


@dataclass
class RoadFit:
    """A fitted road: the OpenDRIVE text and what was fitted.

    ``rms``/``max_error``: distances of the reference polyline's points from the fitted reference
    line [m]. ``reference``: input index of that polyline. ``order``: input indices left to right.
    ``lane_ids``: lane ids left to right. ``line_lane``: for lane centres, the lane id of each input
    line (in input order); for borders, None. ``line_rms``: per input line, RMS of its points'
    lateral distances from the fitted border/centre line [m].
    """

    xodr: str
    road: Road
    reference_line: ReferenceFit
    reference: int
    order: list[int]
    lane_ids: list[int]
    line_lane: list[int] | None
    line_rms: list[float]

    @property
    def rms(self) -> float:
        return self.reference_line.rms

    @property
    def max_error(self) -> float:
        return self.reference_line.max_error

    def network(self):
        """The fitted road as a :class:`~aveas_format.opendrive.network.RoadNetwork`."""
        from aveas_format.opendrive.network import load_map

        return load_map(self.xodr)

    def write(self, path: str | Path) -> Path:
        """Write the OpenDRIVE text to ``path``."""
        from aveas_format.safeio import write_text_atomic

        return write_text_atomic(path, self.xodr)



def fit_road(
    lines: Sequence[Any],
    *,
    kind: str = "centres",
    driving: str = "right",
    left_lanes: int | None = None,
    reference: int | None = None,
    ordered: bool = False,
    lane_width: float = 3.5,
    lane_types: Sequence[str] | None = None,
    mark_types: Sequence[str] | None = None,
    knot_spacing: float = 20.0,
    tolerance: float = 0.005,
    width_spacing: float = 25.0,
    smoothing: float = 0.05,
    snap: bool = True,
    road_id: str = "1",
    name: str = "fitted_road",
    road_type: str | None = None,
    speed_limit: float | None = None,
    geo_reference: str | None = None,
    label: str = "lines",
) -> RoadFit:
    """Fit one OpenDRIVE road (one lane section) to roughly parallel polylines.

    ``lines``: (N, 2) arrays in the local frame, each ordered along the road; the reference line
    runs in the direction of the reference polyline. ``kind``: ``"centres"`` (lane centre lines)
    or ``"borders"`` (lane borders / markings, n borders make n - 1 lanes). ``driving``:
    ``"right"`` (a one-way carriageway: every lane right of the centre lane, ids -1, -2, ...,
    driving along the reference line under right-hand traffic) or ``"both"`` (``left_lanes``
    lanes left of the centre lane, default half of them, the extra one going right).
    ``reference``: input index of the polyline the reference line is fitted to (default the
    centre-most). ``ordered``: the lines are given left to right (as seen along the reference
    polyline) and that order is checked; otherwise they are sorted by their lateral position.
    ``lane_width``: width of the lane of a single centre line. ``lane_types`` (left to right,
    default ``driving``) and ``mark_types`` (borders left to right, default solid outside and
    between the directions, broken elsewhere). ``knot_spacing``/``tolerance``/``smoothing``/``snap``:
    see :func:`fit_reference_line`; ``width_spacing``: metres between the knots of the lateral
    splines. Returns a :class:`RoadFit`; raises :class:`~aveas_format.errors.MapError` for
    malformed input.
    """
    if kind not in ("centres", "centers", "borders"):
        raise ValueError(f"kind must be 'centres' or 'borders', not {kind!r}")
    if driving not in ("right", "both"):
        raise ValueError(f"driving must be 'right' or 'both', not {driving!r}")
    if width_spacing <= 0 or lane_width <= 0:
        raise ValueError("width_spacing and lane_width must be positive")
    borders_in = kind == "borders"
    lines = list(lines) if not isinstance(lines, np.ndarray) or lines.ndim == 3 else [lines]
    n = len(lines)
    if n < (2 if borders_in else 1):
        raise MapError(f"{label}: need at least {2 if borders_in else 1} line(s), got {n}")
    arrs = [as_line(ln, f"{label}[{i}]") for i, ln in enumerate(lines)]
    order = _lateral_order(arrs, ordered, label)
    z = _centre_border(driving, left_lanes, n - 1 if borders_in else n)
    reference, ref_pos = _reference_index(reference, order, z, borders_in, label)

    ref = fit_reference_line(arrs[reference], knot_spacing=knot_spacing, tolerance=tolerance, smoothing=smoothing,
                             snap=snap, label=f"{label}[{reference}]")
    L = ref.length
    probe, samples = _project_lines(arrs, ref, reference, label)
    _check_crossings(samples, order, L, probe, label)
    knots, fits, line_rms = _lateral_splines(samples, reference, L, width_spacing)
    B = _borders([fits[i] for i in order], borders_in, lane_width)
    nb = len(B)
    if mark_types is not None and len(mark_types) != nb:
        raise ValueError(f"mark_types needs {nb} entries (one per border, left to right)")
    if lane_types is not None and len(lane_types) != nb - 1:
        raise ValueError(f"lane_types needs {nb - 1} entries (one per lane, left to right)")
    _check_widths(B, knots, L, label)
    sec, lane_offset, lane_ids = _lane_section(B, knots, L, z, borders_in and ref_pos == z,
                                               lane_types, mark_types)
    types = []
    if road_type is not None or speed_limit is not None:
        types = [RoadType(0.0, road_type or "town", None,
                          None if speed_limit is None else repr(float(speed_limit)),
                          None if speed_limit is None else "m/s")]
    road = Road(id=str(road_id), length=L, name=name, types=types, geometries=ref.geometries,
                lane_offset=lane_offset, lane_sections=[sec])
    from aveas_format.opendrive.builder import roads_xodr

    xodr = roads_xodr([road], name=name, geo_reference=geo_reference)
    line_lane = None
    if not borders_in:
        line_lane = [0] * n
        for pos, i in enumerate(order):
            line_lane[i] = lane_ids[pos]
    return RoadFit(xodr, road, ref, int(reference), order, lane_ids, line_lane, line_rms)


def road_from_lane_markings(
    markings: Sequence[Any],
    driving: str = "right",
    *,
    left_lanes: int | None = None,
    mark_types: Sequence[str] | None = None,
    **kw: Any,
) -> RoadFit:
    """A road from lane marking (border) polylines ordered left to right along the road.

    n markings make n - 1 lanes. ``driving="right"``: one carriageway, all lanes right of the
    reference line (ids -1 .. -(n-1), driving along the markings' direction). ``driving="both"``:
    ``left_lanes`` lanes (default: half, the extra one going right) lie left of the centre
    marking. ``mark_types``: one road mark type per marking (``solid``, ``broken``, ...). Other
    keywords go to :func:`fit_road` (``reference``, ``knot_spacing``, ``geo_reference``, ...).
    """
    return fit_road(markings, kind="borders", driving=driving, left_lanes=left_lanes, ordered=True,
                    mark_types=mark_types, label=kw.pop("label", "markings"), **kw)


def _lateral_order(arrs: list[np.ndarray], ordered: bool, label: str) -> list[int]:
    """Input indices left to right, from the median offsets from a preliminary reference (the
    longest line); with ``ordered``, the input order must be that order."""
    n = len(arrs)
    lens = [float(np.hypot(*np.diff(a, axis=0).T).sum()) for a in arrs]
    pre = int(np.argmax(lens))
    med = np.array([float(np.median(_signed_offsets(arrs[pre], a))) if i != pre else 0.0
                    for i, a in enumerate(arrs)])
    order = [int(i) for i in np.argsort(-med, kind="stable")]
    if ordered and order != list(range(n)):
        bad = next(j for j in range(n) if order[j] != j)
        raise MapError(
            f"{label}: must be ordered left to right (as seen along {label}[{pre}]); "
            f"{label}[{order[bad]}] lies left of {label}[{bad}]"
        )
    return order


def _centre_border(driving: str, left_lanes: int | None, n_lanes: int) -> int:
    """Index (left to right) of the border between the directions: the number of left lanes."""
    if driving == "right":
        return 0
    nl = n_lanes // 2 if left_lanes is None else int(left_lanes)
    if not 0 <= nl <= n_lanes:
        raise ValueError(f"left_lanes must be between 0 and {n_lanes}")
    return nl


def _reference_index(reference: int | None, order: list[int], z: int, borders_in: bool,
                     label: str) -> tuple[int, int]:
    """The input index of the reference polyline (default: the centre-most line, nearest the
    centre border) and its position left to right."""
    n = len(order)
    if reference is None:
        cands = [(n - 1) // 2] if n % 2 else [n // 2 - 1, n // 2]
        target = z if borders_in else z - 0.5
        ref_pos = min(cands, key=lambda c: (abs(c - target), c))
        reference = order[ref_pos]
    if not 0 <= reference < n:
        raise ValueError(f"reference must be an index into {label} (0..{n - 1})")
    return reference, order.index(reference)


def _project_lines(arrs: list[np.ndarray], ref: ReferenceFit, reference: int, label: str):
    """Every line projected onto the exact reference line: the probe network and per line the
    sorted (s, t) of its points within the reference line's s range (t = 0 on the reference)."""
    geoms = ref.geometries
    L = ref.length
    reach = max(float(np.max(np.abs(_signed_offsets(arrs[reference], a)))) for a in arrs) + 2.0
    kmax = max([abs(g.params.get("curvature", 0.0)) for g in geoms]
               + [max(abs(g.params.get("curv_start", 0.0)), abs(g.params.get("curv_end", 0.0))) for g in geoms])
    if reach * kmax >= 0.98:
        raise MapError(
            f"{label}: lines lie up to {reach - 2:.1f} m from the reference line {label}[{reference}], "
            f"beyond its tightest curve radius ({1 / kmax:.1f} m); fit the road in parts or pick "
            "another reference"
        )
    probe = probe_network(geoms, reach)
    samples = []
    for i, a in enumerate(arrs):
        pr = probe.world_to_road(a[:, 0], a[:, 1])
        ok = np.isfinite(pr.s)
        if ok.sum() < 2:
            raise MapError(
                f"{label}[{i}]: does not run alongside the reference line {label}[{reference}] "
                f"(only {int(ok.sum())} of its points lie within its s range 0..{L:.1f} m)"
            )
        si, ti = pr.s[ok], pr.t[ok]
        if i == reference:
            ti = np.zeros_like(ti)
        srt = np.argsort(si)
        samples.append((si[srt], ti[srt]))
    return probe, samples


def _check_crossings(samples: list[tuple[np.ndarray, np.ndarray]], order: list[int], L: float,
                     probe, label: str) -> None:
    """Neighbouring lines (left to right) must keep 5 cm apart where both are observed."""
    grid = np.linspace(0.0, L, max(3, int(L / 1.0) + 1))
    for j in range(len(order) - 1):
        (sa, ta), (sb, tb) = samples[order[j]], samples[order[j + 1]]
        lo, hi = max(sa[0], sb[0]), min(sa[-1], sb[-1])
        g = grid[(grid >= lo) & (grid <= hi)]
        if len(g) == 0:
            continue
        gap = np.interp(g, sa, ta) - np.interp(g, sb, tb)
        if gap.min() <= 0.05:
            at = float(g[int(np.argmin(gap))])
            x, y, _, _ = probe.road_to_world("fit", [at], [float(np.interp(at, sa, ta))])[:4]
            raise MapError(
                f"{label}[{order[j]}] and {label}[{order[j + 1]}] cross or touch near s={at:.1f} m "
                f"({x[0]:.2f}, {y[0]:.2f}); lines must keep their order across the road"
            )


def _lateral_splines(samples: list[tuple[np.ndarray, np.ndarray]], reference: int, L: float,
                     width_spacing: float) -> tuple[np.ndarray, list[np.ndarray], list[float]]:
    """Each line's t(s) as a P-spline on shared knots (the reference line's: t = 0): (knots,
    coefficients per line, RMS of each line's points from its spline)."""
    from scipy.interpolate import BSpline

    n = len(samples)
    fits = []
    for i in range(n):
        knots, c = _pspline(*samples[i], L, width_spacing, 0.05)
        fits.append(np.zeros_like(c) if i == reference else c)
    line_rms = []
    for i in range(n):
        s_i, t_i = samples[i]
        r = BSpline(knots, fits[i], 3)(s_i) - t_i
        line_rms.append(float(np.sqrt(np.mean(r * r))))
    return knots, fits, line_rms


def _borders(C: list[np.ndarray], borders_in: bool, lane_width: float) -> list[np.ndarray]:
    """Border splines left to right from the lines' splines ``C`` (left to right; B-spline
    coefficients are linear in the lines): the lines themselves, or for lane centres the
    midpoints, the outermost half a lane spacing further out (``lane_width`` for one centre)."""
    n = len(C)
    if borders_in:
        return C
    if n == 1:
        return [C[0] + lane_width / 2, C[0] - lane_width / 2]
    return [1.5 * C[0] - 0.5 * C[1]] + [0.5 * (C[j - 1] + C[j]) for j in range(1, n)] + [1.5 * C[-1] - 0.5 * C[-2]]


def _check_widths(B: list[np.ndarray], knots: np.ndarray, L: float, label: str) -> None:
    """Every lane (between neighbouring borders) must stay wider than 5 cm (sampled every 0.5 m)."""
    from scipy.interpolate import BSpline

    dense = np.linspace(0.0, L, max(3, int(L / 0.5) + 1))
    vals = np.array([BSpline(knots, b, 3)(dense) for b in B])
    widths = vals[:-1] - vals[1:]
    if widths.min() <= 0.05:
        j, m = np.unravel_index(int(np.argmin(widths)), widths.shape)
        raise MapError(
            f"{label}: the lane between borders {j} and {j + 1} (left to right) has width "
            f"{widths[j, m]:.3f} m at s={dense[m]:.1f} m; lines must not cross"
        )


def _lane_section(B: list[np.ndarray], knots: np.ndarray, L: float, z: int, offset_is_ref: bool,
                  lane_types: Sequence[str] | None, mark_types: Sequence[str] | None):
    """The lane section of the border splines ``B`` (left to right; ``z``: the border between the
    directions, the centre lane), the lane offset records (none when the reference line is that
    border) and the lane ids left to right."""
    nb = len(B)
    brk, _ = _pieces(knots, B[0])
    coef = [_pieces(knots, b)[1] for b in B]
    lane_offset = (
        []
        if offset_is_ref
        else [Poly3Record(*(float(v) for v in row)) for row in _records(brk, coef[z], L)]
    )

    def mark(b: int) -> RoadMark:
        if mark_types is not None:
            typ = mark_types[b]
        else:
            typ = "solid" if b in (0, nb - 1) or (b == z and 0 < z < nb - 1) else "broken"
        change = "none" if typ == "solid" else "both"
        return RoadMark(0.0, typ, {"weight": "standard", "color": "standard", "width": "0.15",
                                   "laneChange": change})

    left, right = [], []
    for j in range(nb - 1):  # lane between borders j and j+1
        lid = (z - j) if j < z else -(j - z + 1)
        outer = j if lid > 0 else j + 1
        inner = j + 1 if lid > 0 else j
        wcoef = coef[outer] - coef[inner] if lid > 0 else coef[inner] - coef[outer]
        rows = _records(brk, wcoef, L)
        lane = Lane(id=lid, type=lane_types[j] if lane_types is not None else "driving",
                    widths=rows, road_marks=[mark(outer)])
        (left if lid > 0 else right).append(lane)
    left.sort(key=lambda ln: ln.id)
    right.sort(key=lambda ln: -ln.id)
    sec = LaneSection(s=0.0, left=left, center=Lane(id=0, type="none", road_marks=[mark(z)]), right=right)
    lane_ids = [(z - j) if j < z else -(j - z + 1) for j in range(nb - 1)]
    return sec, lane_offset, lane_ids
