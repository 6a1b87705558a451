"""Frame and covariance maths of the ROS 2 MCAP converter: the (x, y, yaw) covariance blocks,
poses and twists from a ROS frame into the map frame with the full Jacobian of the frame change,
and the map frame placed in the OpenDRIVE map's local frame (``frame_offset``)."""

from __future__ import annotations

import numpy as np

from aveas_format.converters.common.geometry import matrix_yaw, quaternion_matrix, rotation_2d


def cov3(flat: np.ndarray) -> np.ndarray:
    """Flat 3x3 blocks -> (n, 3, 3); all-zero or negative-variance blocks (unknown) -> nan."""
    c = np.asarray(flat, np.float64).reshape(-1, 3, 3)
    unknown = np.all(c == 0, axis=(1, 2)) | (c[:, 0, 0] < 0)  # all zero / -1: unknown (ROS custom)
    c = c.copy()
    c[unknown] = np.nan
    return c


def to_map(r_f: np.ndarray, p_f: np.ndarray, cov_f, pose: np.ndarray, pcov: np.ndarray):
    """Object poses in a frame -> map: position, heading, (x, y, yaw) covariance (n,3,3)."""
    pos = np.einsum("nij,nj->ni", r_f, pose[:, :3]) + p_f
    r_obj = np.einsum("nij,njk->nik", r_f, quaternion_matrix(pose[:, 3:]))
    heading = matrix_yaw(r_obj)
    th = matrix_yaw(r_f)
    c, s = np.cos(th), np.sin(th)
    n = len(th)
    j_obj = np.zeros((n, 3, 3))
    j_obj[:, 0, 0], j_obj[:, 0, 1], j_obj[:, 1, 0], j_obj[:, 1, 1] = c, -s, s, c
    j_obj[:, 2, 2] = 1.0
    cov = np.einsum("nij,njk,nlk->nil", j_obj, pcov, j_obj)
    if cov_f is not None:
        # the uncertain frame (the ego) at ``origin`` with pose covariance (x, y, yaw) in map:
        # d pos / d yaw = the lever arm from its origin rotated by 90 degrees
        fcov, origin = cov_f
        lever = pos[:, :2] - origin[:, :2]
        j_f = np.zeros((n, 3, 3))
        j_f[:, 0, 0] = j_f[:, 1, 1] = j_f[:, 2, 2] = 1.0
        j_f[:, 0, 2] = -lever[:, 1]
        j_f[:, 1, 2] = lever[:, 0]
        cov = cov + np.einsum("nij,njk,nlk->nil", j_f, fcov, j_f)
    return pos, heading, cov, th


def twist_to_map(angle: np.ndarray, twist: np.ndarray, tcov: np.ndarray, var_angle: np.ndarray):
    """Rotate (vx, vy) by ``angle``; covariance R V R^T + g var(angle) g^T."""
    r = rotation_2d(angle)
    v = np.einsum("nij,nj->ni", r, twist[:, :2])
    cov = np.einsum("nij,njk,nlk->nil", r, tcov[:, :2, :2], r)
    g = np.stack([-v[:, 1], v[:, 0]], -1)  # d(R v)/d angle
    cov = cov + np.nan_to_num(var_angle)[:, None, None] * np.einsum("ni,nj->nij", g, g)
    return v, cov


def apply_offset(offset, x, y, heading, cov_xy, vx, vy, cov_v):
    """Map-frame positions, headings, velocities and their covariances -> the OpenDRIVE map's
    local frame, in which the map frame has the pose ``offset`` = (x, y, yaw)."""
    ox, oy, oyaw = offset
    if oyaw:
        c, s = np.cos(oyaw), np.sin(oyaw)
        x, y = c * x - s * y, s * x + c * y
        vx, vy = c * vx - s * vy, s * vx + c * vy
        r = rotation_2d(np.full(len(x), oyaw))
        cov_xy = np.einsum("nij,njk,nlk->nil", r, cov_xy, r)
        cov_v = np.einsum("nij,njk,nlk->nil", r, cov_v, r)
        heading = heading + oyaw
    return x + ox, y + oy, np.angle(np.exp(1j * heading)), cov_xy, vx, vy, cov_v
