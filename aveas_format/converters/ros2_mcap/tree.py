"""The transform tree: transform samples collected from /tf, /tf_static, the odometry and the
NavSatFix ego track, looked up (interpolated, chained to the map frame, with the ego's pose
covariance carried along) at the messages' stamps."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from aveas_format.converters.common.geometry import matrix_yaw, quaternion_matrix, rotation_2d
from aveas_format.errors import FormatError


@dataclass
class TransformSamples:
    """Transform samples: child -> (parent, t_ns, translation, quaternion, static, source)."""

    data: dict[str, dict[str, Any]] = field(default_factory=dict)

    def add(self, parent: str, child: str, t_ns: int, tr: tuple, q: tuple, static: bool,
            source: str) -> None:
        e = self.data.setdefault(child, {"parent": parent, "t": [], "tr": [], "q": [],
                                         "static": static, "source": source})
        if e["parent"] != parent:
            return  # a frame has one parent; later conflicting edges are ignored
        e["t"].append(t_ns)
        e["tr"].append(tr)
        e["q"].append(q)


class TransformTree:
    """The transforms by child frame: each frame's parent, sample times, translations and
    quaternions (static frames: one sample), and for the ego's frame its pose covariance."""

    def __init__(self, edges: TransformSamples, map_frame: str, tol_ns: int):
        self.map = map_frame
        self.tol = tol_ns
        self.e: dict[str, dict[str, Any]] = {}
        for child, d in edges.data.items():
            t = np.asarray(d["t"], np.int64)
            order = np.argsort(t, kind="stable")
            t = t[order]
            keep = np.r_[True, np.diff(t) > 0]
            self.e[child] = {"parent": d["parent"], "t": t[keep],
                             "tr": np.asarray(d["tr"], np.float64)[order][keep],
                             "q": np.asarray(d["q"], np.float64)[order][keep],
                             "static": d["static"] or keep.sum() == 1, "source": d["source"],
                             "cov": None}

    def add(self, parent: str, child: str, t: np.ndarray, tr: np.ndarray, q: np.ndarray,
            cov: np.ndarray | None, source: str) -> None:
        self.e[child] = {"parent": parent, "t": t, "tr": tr, "q": q, "static": False,
                         "source": source, "cov": cov}

    def reaches(self, frame: str, target: str) -> bool:
        for _ in range(64):
            if frame == target:
                return True
            if frame not in self.e:
                return False
            frame = self.e[frame]["parent"]
        return False

    def _edge_at(self, e: dict[str, Any], t: np.ndarray):
        from scipy.spatial.transform import Rotation, Slerp

        m = len(t)
        if e["static"] or len(e["t"]) == 1:
            r = np.repeat(quaternion_matrix(e["q"][-1:]), m, axis=0)
            return r, np.repeat(e["tr"][-1:], m, axis=0), np.ones(m, bool), None
        te = e["t"]
        ok = self._inside(e, t)
        tc = np.clip(t, te[0], te[-1])
        base = te[0]
        tf = (tc - base).astype(np.float64)
        tef = (te - base).astype(np.float64)
        tr = np.stack([np.interp(tf, tef, e["tr"][:, k]) for k in range(3)], -1)
        # within the tolerance beyond the ends: extrapolate the translation linearly
        tq = (t - base).astype(np.float64)
        lo, hi = tq < tef[0], tq > tef[-1]
        if len(tef) > 1 and (lo.any() or hi.any()):
            s0 = (e["tr"][1] - e["tr"][0]) / (tef[1] - tef[0])
            s1 = (e["tr"][-1] - e["tr"][-2]) / (tef[-1] - tef[-2])
            tr[lo] += np.outer(tq[lo] - tef[0], s0)
            tr[hi] += np.outer(tq[hi] - tef[-1], s1)
        rot = Slerp(tef, Rotation.from_quat(e["q"]))(tf)
        cov = None
        if e["cov"] is not None:
            cov = np.stack([np.interp(tf, tef, e["cov"][:, k]) for k in range(9)], -1).reshape(m, 3, 3)
        return rot.as_matrix(), tr, ok, cov

    def _inside(self, e: dict[str, Any], t: np.ndarray) -> np.ndarray:
        """Whether the stamps ``t`` lie in a dynamic edge's time span (+- the tolerance)."""
        return (t >= e["t"][0] - self.tol) & (t <= e["t"][-1] + self.tol)

    def valid(self, frame: str, t: np.ndarray) -> np.ndarray:
        """The ``ok`` of :meth:`lookup` alone (whether ``t`` lies in the time spans of the
        dynamic transforms of the chain from ``frame`` to the map frame), without the poses."""
        ok = np.ones(len(t), bool)
        cur = frame
        for _ in range(64):
            if cur == self.map:
                return ok
            e = self.e[cur]
            if not (e["static"] or len(e["t"]) == 1):
                ok &= self._inside(e, t)
            cur = e["parent"]
        raise FormatError(f"transform chain of frame {frame!r} is too deep or cyclic")

    def lookup(self, frame: str, t: np.ndarray, want_cov: bool = True):
        """Pose of ``frame`` in the map frame at ``t``: R (m,3,3), p (m,3), ok (m,) (inside the
        dynamic transforms' time spans), and the (x, y, yaw) pose covariance (m,3,3) of the
        uncertain frame in the chain (the ego) with that frame's origin in map (m,3), or None."""
        m = len(t)
        r_acc = np.repeat(np.eye(3)[None], m, axis=0)
        p_acc = np.zeros((m, 3))
        ok = np.ones(m, bool)
        cov_acc = None
        cov_child = None
        cur = frame
        for _ in range(64):
            if cur == self.map:
                if cov_acc is None or not want_cov:
                    return r_acc, p_acc, ok, None
                origin = p_acc if cov_child == frame else self.lookup(cov_child, t, False)[1]
                return r_acc, p_acc, ok, (cov_acc, origin)
            e = self.e[cur]
            r, p, ok_e, cov = self._edge_at(e, t)
            ok &= ok_e
            if cov_acc is not None:  # expressed in cur: rotate into the parent
                r2 = rotation_2d(matrix_yaw(r))
                cov_acc = cov_acc.copy()
                cov_acc[:, :2, :2] = np.einsum("nij,njk,nlk->nil", r2, cov_acc[:, :2, :2], r2)
            if want_cov and cov is not None and cov_acc is None:
                cov_acc, cov_child = np.nan_to_num(cov), cur
            r_acc = np.einsum("nij,njk->nik", r, r_acc)
            p_acc = np.einsum("nij,nj->ni", r, p_acc) + p
            cur = e["parent"]
        raise FormatError(f"transform chain of frame {frame!r} is too deep or cyclic")
