"""Coordinate systems as OpenLABEL files chain them: poses, and the transform of any system into
the root through static poses (``pose_wrt_parent``) and per-frame transforms
(``frame_properties.transforms``).

Used by the ``openlabel`` import (cuboids in any coordinate system) and by ``infra-lidar`` (TUM
Traffic's OpenLABEL label files, their sensor poses): :func:`pose` reads a pose (``matrix4x4``,
quaternion or Euler angles), :class:`CoordinateSystems` resolves a system into the root,
:func:`utm_crs` reads a UTM root's zone from its name.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from typing import Any

import numpy as np

from aveas_format.converters.common.geometry import quaternion_matrix
from aveas_format.errors import FormatError


def quaternion_rotation(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    """The 3x3 rotation of one quaternion (:func:`~.geometry.quaternion_matrix`; NaN where a
    component is: no identity in its place)."""
    q = np.array([qx, qy, qz, qw], np.float64)
    return quaternion_matrix(q)[0] if np.isfinite(q).all() else np.full((3, 3), np.nan)


def axis_rotation(axis: str, angle: float) -> np.ndarray:
    """The 3x3 rotation by ``angle`` about ``axis`` (``"X"``, ``"Y"``, else Z)."""
    c, s_ = math.cos(angle), math.sin(angle)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s_], [0, s_, c]])
    if axis == "Y":
        return np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
    return np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])


def euler_rotation(rx: float, ry: float, rz: float) -> np.ndarray:
    """ZYX (yaw, pitch, roll): OpenLABEL's default sequence."""
    return axis_rotation("Z", rz) @ axis_rotation("Y", ry) @ axis_rotation("X", rx)


def pose(tf: dict[str, Any] | list | None, where: str = "a transform") -> np.ndarray | None:
    """A 4x4 matrix of an OpenLABEL pose/transform: ``matrix4x4`` (row-major), or ``quaternion``
    (x, y, z, w) / ``euler_angles`` (values in the order of ``sequence``, default ZYX, i.e.
    (rz, ry, rx)) with ``translation``. One that does not read as such (16 numbers, 4 of the
    quaternion, 3 of the translation...) is a :class:`FormatError` naming ``where``."""
    if tf is None:
        return None
    try:
        m = _pose_matrix(tf)
    except (TypeError, ValueError, KeyError, IndexError, AttributeError) as e:
        raise FormatError(f"OpenLABEL: {where} is no readable pose ({type(e).__name__}: {e}): "
                          f"{str(tf)[:120]}") from None
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise FormatError(f"OpenLABEL: {where} is no finite 4x4 pose: {str(tf)[:120]}")
    return m


def _pose_matrix(tf: dict[str, Any] | list) -> np.ndarray:
    if isinstance(tf, list):
        tf = {"matrix4x4": tf}
    m = np.eye(4)
    if tf.get("matrix4x4") is not None:
        return np.asarray(tf["matrix4x4"], float).reshape(4, 4)
    if tf.get("quaternion") is not None:
        m[:3, :3] = quaternion_rotation(*tf["quaternion"])
    elif tf.get("euler_angles") is not None:
        seq = str(tf.get("sequence") or "ZYX").upper()
        R = np.eye(3)
        for axis, angle in zip(seq, tf["euler_angles"]):
            R = R @ axis_rotation(axis, float(angle))
        m[:3, :3] = R
    if tf.get("translation") is not None:
        m[:3, 3] = np.asarray(tf["translation"], float)[:3]
    return m



class CoordinateSystems:
    """The coordinate systems of a file: static poses (``pose_wrt_parent``, ``X_parent = P X``)
    and, per frame, ``frame_properties.transforms`` (``transform_src_to_dst``). :meth:`resolve`
    finds the transform of a coordinate system into the root: a breadth-first search over both
    (a frame's transforms first, either direction), to the reachable root of the highest rank (a
    geo or scene coordinate system, else the root of its own tree)."""

    def __init__(self, cs: dict[str, Any] | None) -> None:
        self.cs = cs if isinstance(cs, dict) else {}
        self.parent = {k: (v or {}).get("parent") or None for k, v in self.cs.items()}
        self.static = {k: pose((v or {}).get("pose_wrt_parent"), f"the pose_wrt_parent of coordinate system {k}")
                       for k, v in self.cs.items()}
        self.kind = {k: str((v or {}).get("type") or "") for k, v in self.cs.items()}
        self.children: dict[str, list[str]] = defaultdict(list)
        for k, p in self.parent.items():
            if p:
                self.children[p].append(k)
        self.unknown: set[str] = set()

    def root_of(self, name: str | None) -> str | None:
        seen = set()
        while name and self.parent.get(name) and name not in seen:
            seen.add(name)
            name = self.parent[name]
        return name

    @staticmethod
    def frame_edges(transforms: Any) -> dict[str, list[tuple[str, np.ndarray]]]:
        """The transforms of a frame as edges ``src -> [(dst, 4x4 X_dst = T X_src)]``, both ways."""
        edges: dict[str, list[tuple[str, np.ndarray]]] = defaultdict(list)
        for tf in (transforms or {}).values() if isinstance(transforms, dict) else ():
            if not (isinstance(tf, dict) and tf.get("src") and tf.get("dst")):
                continue
            m = pose(tf.get("transform_src_to_dst"), f"the transform {tf['src']} -> {tf['dst']}")
            if m is None:
                continue
            src, dst = str(tf["src"]), str(tf["dst"])
            edges[src].append((dst, m))
            try:
                edges[dst].append((src, np.linalg.inv(m)))
            except np.linalg.LinAlgError:
                pass
        return edges

    def resolve(self, name: str | None, edges: dict[str, list] | None = None
                ) -> tuple[np.ndarray, str | None, bool]:
        """``(4x4 name -> root, root, whether a frame transform is on the path)``. A name that is
        not among ``coordinate_systems`` and has no frame transform is taken as the root."""
        if not name:
            return np.eye(4), None, False
        edges = edges or {}
        if name not in self.cs and name not in edges:
            self.unknown.add(name)
            return np.eye(4), name, False
        best: dict[str, tuple[np.ndarray, bool]] = {name: (np.eye(4), False)}
        queue = [name]
        while queue:
            n = queue.pop(0)
            m, used = best[n]
            steps = [(d, t, True) for d, t in edges.get(n, ())]
            p = self.parent.get(n)
            if p:
                steps.append((p, self.static.get(n) if self.static.get(n) is not None else np.eye(4), False))
            for c in self.children.get(n, ()):
                st = self.static.get(c)
                steps.append((c, np.linalg.inv(st) if st is not None else np.eye(4), False))
            for d, t, frame in steps:
                if d not in best:
                    best[d] = (t @ m, used or frame)
                    queue.append(d)
        own_root = self.root_of(name)
        roots = [n for n in best if not self.parent.get(n)]

        def rank(r: str) -> tuple:
            kind = self.kind.get(r, "")
            return (kind.startswith("geo"), kind == "scene_cs", r == own_root,
                    -list(best).index(r))

        root = max(roots, key=rank) if roots else own_root
        m, used = best.get(root, (np.eye(4), False))
        return m, root, used


def utm_crs(name: str) -> str | None:
    """EPSG code of a UTM coordinate system named like ``utm-30t`` / ``UTM32N`` (band letters C-M
    are southern, N-X northern; no letter = northern)."""
    mt = re.search(r"utm[-_ ]?(\d{1,2})\s*([c-xC-X])?(?![a-zA-Z])", name or "", re.I)
    if not mt:
        return None
    zone = int(mt[1])
    south = bool(mt[2]) and mt[2].upper() < "N"
    return f"EPSG:{32700 + zone if south else 32600 + zone}"
