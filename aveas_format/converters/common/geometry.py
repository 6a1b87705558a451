"""Geometry of source frames: reference points moved along the heading, angle conventions,
rotations (quaternions, 2D), vectors and their std turned, covariances turned and reduced to std and correlation, oriented box
corners, points of a projected source CRS in the map's local frame, and the CRS of the map's frame
(:func:`map_crs`: its geoReference, else the import's ``crs`` option)."""

from __future__ import annotations

import numpy as np

from aveas_format.numeric import wrap_angle


def move_along_heading(x: np.ndarray, y: np.ndarray, heading: np.ndarray, d: np.ndarray | float
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Move points by ``d`` metres along their heading (negative = backwards).

    SUMO's front bumper -> footprint centre is ``d = -length / 2``.
    """
    return x + d * np.cos(heading), y + d * np.sin(heading)


def navigation_deg_to_heading(angle_deg: np.ndarray) -> np.ndarray:
    """Navigational degrees (0 = north, clockwise) -> heading (rad, counter-clockwise from +x,
    wrapped to (-pi, pi])."""
    return wrap_angle(np.pi / 2 - np.radians(angle_deg))


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotation matrices of (n, 4) quaternions ``(qx, qy, qz, qw)`` (normalised here;
    an all-zero quaternion counts as identity)."""
    q = np.atleast_2d(np.asarray(q, np.float64))
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(norm > 0, q / np.where(norm > 0, norm, 1.0), np.array([0.0, 0.0, 0.0, 1.0]))
    x, y, z, w = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def matrix_yaw(r: np.ndarray) -> np.ndarray:
    """Yaw (rad, CCW from +x) of the body x-axis of (n, 3, 3) rotations, projected on the ground."""
    r = np.asarray(r)
    return np.arctan2(r[..., 1, 0], r[..., 0, 0])


def rotation_2d(theta: np.ndarray) -> np.ndarray:
    """(n, 2, 2) rotation matrices."""
    c, s = np.cos(theta), np.sin(theta)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=-2)


def rotate_covariance_2d(cov: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """R(theta) C R(theta)^T for (n, 2, 2) covariances."""
    r = rotation_2d(np.asarray(theta, np.float64))
    return np.einsum("nij,njk,nlk->nil", r, cov, r)


def covariance_std_corr(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(sx, sy, corr) of (n, 2, 2) covariances; NaN stays NaN (unknown), corr is 0 where a
    standard deviation is 0, and clipped to [-1, 1]."""
    sx = np.sqrt(np.clip(cov[:, 0, 0], 0.0, None))
    sy = np.sqrt(np.clip(cov[:, 1, 1], 0.0, None))
    den = sx * sy
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = np.where(den > 0, cov[:, 0, 1] / np.where(den > 0, den, 1.0), 0.0)
    corr = np.where(np.isnan(den), np.nan, np.clip(corr, -1.0, 1.0))
    return sx, sy, corr


def rotate(vx: np.ndarray, vy: np.ndarray, angle: np.ndarray | float
           ) -> tuple[np.ndarray, np.ndarray]:
    """Vectors rotated counter-clockwise by ``angle`` (rad)."""
    c, s = np.cos(angle), np.sin(angle)
    return vx * c - vy * s, vx * s + vy * c


def rotated_std(sx: np.ndarray, sy: np.ndarray, corr: np.ndarray | None, angle: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """1-sigma of a Gaussian 2D vector's components (std ``sx``, ``sy``, correlation ``corr``;
    None: 0) along axes turned counter-clockwise by ``angle`` (a world vector's in the frame of a
    vehicle heading ``angle``)."""
    r = np.zeros_like(sx) if corr is None else np.nan_to_num(corr)
    c, s = np.cos(angle), np.sin(angle)
    cxy = r * sx * sy
    vu = c * c * sx * sx + s * s * sy * sy + 2 * c * s * cxy
    vv = s * s * sx * sx + c * c * sy * sy - 2 * c * s * cxy
    return np.sqrt(np.maximum(vu, 0)), np.sqrt(np.maximum(vv, 0))


def footprint_corners(x: np.ndarray, y: np.ndarray, heading: np.ndarray, length: np.ndarray,
                      width: np.ndarray) -> np.ndarray:
    """(n, 4, 2) corners (front-left, rear-left, rear-right, front-right) of oriented boxes."""
    c, s = np.cos(heading), np.sin(heading)
    hl, hw = np.asarray(length) / 2.0, np.asarray(width) / 2.0
    out = np.empty((len(x), 4, 2))
    for k, (a, b) in enumerate(((1, 1), (-1, 1), (-1, -1), (1, -1))):
        out[:, k, 0] = x + a * hl * c - b * hw * s
        out[:, k, 1] = y + a * hl * s + b * hw * c
    return out


def projected_to_local(x: np.ndarray, y: np.ndarray, source_crs: str, map_crs: str,
                       map_offset: tuple[float, float, float, float] | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points in a projected source CRS (UTM, a world file's CRS, ...) -> the map's local frame
    (its ``geoReference`` ``map_crs`` and header ``<offset>``).

    Returns ``(x, y, rotation)``: ``rotation`` (rad, per point or scalar) is the angle that source
    directions turn by in the local frame: add it to source headings and rotate source vectors by
    it (:func:`rotate`). It holds the header offset's ``hdg`` and, where the two CRSs differ, the
    local grid convergence between them (measured by projecting a point 1 m east of each point).
    """
    from aveas_format.crs import LocalFrame, crs_equal, parse_crs

    frame = LocalFrame(map_crs, map_offset, warn=False)
    hdg = frame.offset[3]
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if crs_equal(source_crs, map_crs):
        lx, ly = frame.from_projected(x, y)
        return lx, ly, np.full(x.shape, -hdg)
    import pyproj

    tr = pyproj.Transformer.from_crs(parse_crs(source_crs).crs, parse_crs(map_crs).crs,
                                     always_xy=True)
    px, py = (np.asarray(a, np.float64) for a in tr.transform(x, y))
    qx, qy = (np.asarray(a, np.float64) for a in tr.transform(x + 1.0, y))
    rot = np.arctan2(qy - py, qx - px) - hdg
    lx, ly = frame.from_projected(px, py)
    return lx, ly, rot


def map_crs(header, options) -> str | None:
    """The CRS of the map's frame for an import: the map's ``<geoReference>``, else the import's
    shared ``crs`` option (``--crs``; where it means the recording's CRS), else None. A converter
    that needs it to project lon/lat raises :func:`missing_crs` on None."""
    if header.geo_reference:
        return header.geo_reference
    if getattr(options, "crs_is_recording_crs", True) and getattr(options, "crs", None):
        return options.crs
    return None


def missing_crs(what: str, path=None):
    """The error of an import that needs the map frame's CRS where neither the map nor the source
    nor ``--crs`` gives it (:class:`~aveas_format.errors.MissingCrsError`: the CLI adds the command
    with ``--crs``)."""
    from aveas_format.errors import MissingCrsError

    err = MissingCrsError(f"{what}: the map has no <geoReference> and no --crs is given (API: crs=); "
                          "pass the recording's CRS with --crs", path=path)
    err.what = what  # (the CLI's message with the command keeps it)
    return err
