"""The geometry of generic OpenLABEL files: coordinate systems, poses and cuboids in the root frame.

Generic files place cuboids in any coordinate system: :class:`CoordinateSystems` chains them to the
root through ``coordinate_systems`` ``pose_wrt_parent`` and per-frame ``frame_properties.transforms``
(:func:`pose`: ``matrix4x4``, quaternion or Euler angles); :func:`place` turns the cuboids of many
boxes into centres, yaw, sizes and ground heights in the root frame (the profile's level boxes in
the root frame in one step); :func:`utm_crs` reads a UTM root's zone from its name;
:func:`static_cuboids` finds objects whose static cuboid a frame's transforms move.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict
from typing import Any, Callable

import numpy as np

from aveas_format.errors import FormatError


def _quat_matrix(qx: float, qy: float, qz: float, qw: float) -> np.ndarray:
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) or 1.0
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return np.array([
        [1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qz * qw), 2 * (qx * qz + qy * qw)],
        [2 * (qx * qy + qz * qw), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qx * qw)],
        [2 * (qx * qz - qy * qw), 2 * (qy * qz + qx * qw), 1 - 2 * (qx * qx + qy * qy)]])


def _euler_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """ZYX (yaw, pitch, roll) — OpenLABEL's default sequence."""
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    return Rz @ Ry @ Rx


def _axis_rotation(axis: str, angle: float) -> np.ndarray:
    c, s_ = math.cos(angle), math.sin(angle)
    if axis == "X":
        return np.array([[1, 0, 0], [0, c, -s_], [0, s_, c]])
    if axis == "Y":
        return np.array([[c, 0, s_], [0, 1, 0], [-s_, 0, c]])
    return np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])


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
        m[:3, :3] = _quat_matrix(*tf["quaternion"])
    elif tf.get("euler_angles") is not None:
        seq = str(tf.get("sequence") or "ZYX").upper()
        R = np.eye(3)
        for axis, angle in zip(seq, tf["euler_angles"]):
            R = R @ _axis_rotation(axis, float(angle))
        m[:3, :3] = R
    if tf.get("translation") is not None:
        m[:3, 3] = np.asarray(tf["translation"], float)[:3]
    return m


#: coordinate-system types that are a world frame (preferred as the root of a chain)
WORLD_TYPES = ("geo_utm", "geo_wgs84", "scene_cs")


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

    def to_root(self, name: str | None, transforms: dict[str, Any] | None) -> np.ndarray:
        return self.resolve(name, self.frame_edges(transforms))[0]


def utm_crs(name: str, cs_type: str | None) -> str | None:
    """EPSG code of a UTM coordinate system named like ``utm-30t`` / ``UTM32N`` (band letters C-M
    are southern, N-X northern; no letter = northern)."""
    mt = re.search(r"utm[-_ ]?(\d{1,2})\s*([c-xC-X])?(?![a-zA-Z])", name or "", re.I)
    if not mt:
        return None
    zone = int(mt[1])
    south = bool(mt[2]) and mt[2].upper() < "N"
    return f"EPSG:{32700 + zone if south else 32600 + zone}"




def place(v: np.ndarray, nval: np.ndarray, cs: np.ndarray, resolve: Callable[[int], tuple],
          where: Callable[[int], str]) -> dict[str, np.ndarray]:
    """The cuboids of ``n`` boxes in the root frame: ``v`` their values (``n x 10``, NaN after the
    ``nval`` given), ``cs`` their coordinate systems (None: the root); ``resolve(i)`` gives box
    ``i``'s ``(4x4 -> root, root, moving)``, ``where(i)`` names it in an error (``v``: n x 9 where
    every cuboid has 9 values). Columns ``px, py,
    pz`` (the ground point), ``yaw``, ``dl, dw, dh`` and ``csroot``.

    Level boxes of 9 values in the root frame (the AVEAS profile) are taken as they are. Other
    cuboids are read through their rotation (9 values: Euler angles ZYX; 10: a quaternion) and
    their coordinate system's transform: the axis nearest the root's vertical carries the height,
    the first other axis (the cuboid's x, unless x is the vertical) the length and the heading,
    the remaining one the width; the ground point lies half the box's vertical extent below the
    centre. So a camera-frame cuboid (KITTI's ``CAM_LEFT``: x right, y down, z forward; sizes
    along those axes) comes out with its height from y."""
    n = len(nval)
    simple = (nval == 9) & (v[:, 3] == 0.0) & (v[:, 4] == 0.0) & np.equal(cs, None)
    out = {"px": v[:, 0].copy(), "py": v[:, 1].copy(), "pz": v[:, 2] - v[:, 8] / 2.0, "yaw": v[:, 5].copy(),
           "dl": v[:, 6].copy(), "dw": v[:, 7].copy(), "dh": v[:, 8].copy(), "csroot": np.full(n, None, object)}
    for i in np.flatnonzero(~simple).tolist():
        k = int(nval[i])
        if k not in (9, 10):
            raise FormatError(f"{where(i)}: cuboid with {k} values (expected 9: x, y, z, rx, ry, rz, sx, "
                              "sy, sz or 10: x, y, z, qx, qy, qz, qw, sx, sy, sz)")
        R = _quat_matrix(*v[i, 3:7]) if k == 10 else _euler_matrix(*v[i, 3:6])
        size = v[i, k - 3:k]
        M, root, _ = resolve(i)
        Rw = M[:3, :3] @ R
        pw = M[:3, :3] @ v[i, :3] + M[:3, 3]
        up = np.abs(Rw[2, :])
        kv = int(np.argmax(up))
        kl, kw = (j for j in range(3) if j != kv)
        out["px"][i], out["py"][i], out["yaw"][i] = pw[0], pw[1], math.atan2(Rw[1, kl], Rw[0, kl])
        out["pz"][i] = float(pw[2] - 0.5 * float(up @ np.abs(size)))
        out["dl"][i], out["dw"][i], out["dh"][i] = size[kl], size[kw], size[kv]
        out["csroot"][i] = root
    return out


def static_cuboids(objects: Any) -> list[tuple[str, dict[str, Any], list | None]]:
    """``(object, cuboid, frame intervals or None)`` of the objects with a cuboid in their static
    ``object_data`` in a named coordinate system (KITTI's ego car in ``vehicle-iso8855``: where a
    frame's transforms move that system, the object gets a box in that frame)."""
    out = []
    for u, obj in (objects.items() if isinstance(objects, dict) else ()):
        od = obj.get("object_data") if isinstance(obj, dict) else None
        cubs = od.get("cuboid") if isinstance(od, dict) else None
        cubs = [cubs] if isinstance(cubs, dict) else (cubs if isinstance(cubs, list) else [])
        cub = next((c for c in cubs if isinstance(c, dict) and c.get("val") is not None
                    and c.get("coordinate_system")), None)
        if cub is not None:
            fis = obj.get("frame_intervals")
            out.append((str(u), cub, fis if isinstance(fis, list) and fis else None))
    return out


def in_intervals(k: Any, intervals: list | None) -> bool:
    """Whether frame key ``k`` lies in ``frame_intervals`` (None: everywhere)."""
    if intervals is None:
        return True
    try:
        f = int(k)
    except (TypeError, ValueError):
        return True
    return any(isinstance(fi, dict) and int(fi.get("frame_start", f)) <= f <= int(fi.get("frame_end", f))
               for fi in intervals)
