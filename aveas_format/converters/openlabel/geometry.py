"""The cuboids of generic OpenLABEL files in the root frame.

:func:`place` turns the cuboids of many boxes into centres, yaw, sizes and ground heights in the
root frame (the profile's level boxes in one step; the others through their coordinate system,
:class:`~aveas_format.converters.common.coordinate_systems.CoordinateSystems`);
:func:`static_cuboids` finds objects whose static cuboid a frame's transforms move.
"""

from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from aveas_format.converters.common.coordinate_systems import euler_rotation, quaternion_rotation
from aveas_format.errors import FormatError


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
        R = quaternion_rotation(*v[i, 3:7]) if k == 10 else euler_rotation(*v[i, 3:6])
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
