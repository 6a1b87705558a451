"""What several derivations share: the states rows as numpy arrays, their road coordinates, the
segmentation of ``(participant_id, time)``-sorted rows and ragged index arithmetic.

- :class:`Samples`: the states columns that the pair computations need (positions, heading,
  velocities and their uncertainty), the participants' sizes per row and the accelerations and
  smoothed speed of ``derived/kinematics`` per row (``interactions``, ``encroachments``);
- :func:`road_columns` / :func:`string_values`: road id, lane and ``road_s`` per row
  (``interactions``, ``traffic``) and string columns as object arrays (``events``);
- :func:`segments`: tracks split at a new participant or a time gap (``kinematics``, ``events``);
- :func:`ragged`: the index expansion of concatenated segments, and :func:`searchsorted_segments`:
  a vectorised bisection within segments of a sorted array.

Numeric columns are read with :func:`aveas_format.io.arrow.column_numpy`. The leading underscore
keeps the plugin loader from importing this module as a derivation (it registers nothing).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.errors import FormatError
from aveas_format.io.arrow import column_numpy


class Samples:
    """The states rows as numpy arrays plus what the pair computations need.

    An absent or undefined (null, NaN, ±inf) heading, velocity, standard deviation or correlation
    reads as 0; ``tstep`` numbers the distinct time steps (times closer than ``time_resolution`` s are
    one step)."""

    def __init__(self, rec, time_resolution: float = 1e-6) -> None:
        s = rec.states
        self.pid = s.column("participant_id").to_numpy()
        self.t, self.x, self.y = (column_numpy(s, c, missing=np.nan) for c in ("time", "x", "y"))
        (self.h, self.vx, self.vy, self.sx, self.sy, self.rxy, self.svx, self.svy, self.rv,
         self.sh) = (column_numpy(s, c, nonfinite=0.0, missing=0.0) for c in
                     ("heading", "vx", "vy", "x_std", "y_std", "xy_corr", "vx_std", "vy_std",
                      "vxvy_corr", "heading_std"))
        size = _sizes(rec, self.pid)
        self.L, self.W = size["length"], size["width"]
        self.sL, self.sW = size["length_std"], size["width_std"]
        kin = _kinematics_columns(rec, self.pid, self.t,
                                  ("ax", "ay", "ax_std", "ay_std", "speed", "speed_std"))
        self.ax, self.ay, self.sax, self.say = _accel(rec, kin[:4])
        # smoothed speed and velocity (interactions.velocities.smoothed_velocities); the velocity
        # is NaN where the kinematics table has none (written before it carried vx/vy)
        self.k_speed, self.k_speed_std = kin[4:]
        self.k_vx, self.k_vy, self.k_svx, self.k_svy, self.k_rv = _kinematics_columns(
            rec, self.pid, self.t, ("vx", "vy", "vx_std", "vy_std", "vxvy_corr"))
        # smoothed positions (NaN where none); ``shift``: smoothed minus measured position where
        # the smoothed one replaced it (interactions.velocities.smoothed_velocities)
        self.k_x, self.k_y, self.k_sx, self.k_sy, self.k_rxy = _kinematics_columns(
            rec, self.pid, self.t, ("x", "y", "x_std", "y_std", "xy_corr"))
        self.shift_x = self.shift_y = None
        tk = np.round(self.t / time_resolution).astype(np.int64)
        self.tstep = np.unique(tk, return_inverse=True)[1].ravel()
        self.n = len(self.t)


def _sizes(rec, pid: np.ndarray) -> dict[str, np.ndarray]:
    p = rec.participants
    ids = p.column("participant_id").to_numpy()
    order = np.argsort(ids)
    pos = np.searchsorted(ids[order], pid)
    pos = np.clip(pos, 0, len(ids) - 1)
    found = ids[order][pos] == pid
    if not found.all():
        bad = int(pid[~found][0])
        raise FormatError(f"derivation interactions: table states: participant {bad} is not in "
                          "table participants")
    rows = order[pos]
    out = {}
    for c in ("length", "width"):
        out[c] = column_numpy(p, c, missing=np.nan)[rows]
    for c in ("length_std", "width_std"):
        out[c] = column_numpy(p, c, nonfinite=0.0, missing=0.0)[rows]
    return out


def _accel(rec, derived: tuple[np.ndarray, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                           np.ndarray]:
    """ax, ay and their std per states row: the measured ``ax``/``ay`` of states where present,
    otherwise ``derived`` (those of derived/kinematics; NaN where neither has them)."""
    s = rec.states
    measured = tuple(column_numpy(s, c, missing=np.nan) for c in ("ax", "ay", "ax_std", "ay_std"))
    have = np.isfinite(measured[0]) & np.isfinite(measured[1])
    return tuple(np.where(have, m, d) for m, d in zip(measured, derived))


def _kinematics_columns(rec, pid: np.ndarray, t: np.ndarray, cols: tuple[str, ...]):
    """Columns of derived/kinematics per states row (NaN where it has no such row or no table)."""
    k = rec.derived.get("kinematics")
    n = len(t)
    if k is None or not set(cols) <= set(k.column_names):
        return (np.full(n, np.nan),) * len(cols)
    kp = k.column("participant_id").to_numpy()
    kt = column_numpy(k, "time", missing=np.nan)
    if len(kp) == n and np.array_equal(kp, pid) and np.array_equal(kt, t):
        rows = np.arange(n)
        ok = np.ones(n, bool)
    elif len(kp) == 0:
        return (np.full(n, np.nan),) * len(cols)
    else:
        korder = np.lexsort((kt, kp))
        rows, ok = find_rows(kp[korder], kt[korder], pid, t)
        rows = korder[rows]
    return tuple(np.where(ok, column_numpy(k, c)[rows], np.nan) for c in cols)


# --- road columns and strings --------------------------------------------------------------------

def string_values(table: pa.Table, name: str) -> np.ndarray:
    """A (dictionary) string column as an object array of str, None where null (one str object
    per distinct value: a column of a few categories over millions of rows is a gather)."""
    out = []
    for a in table.column(name).chunks:
        if pa.types.is_null(a.type):
            out.append(np.full(len(a), None, object))
            continue
        if not pa.types.is_dictionary(a.type):
            a = pc.dictionary_encode(a)
        names = np.array([*a.dictionary.to_pylist(), None], object)
        out.append(names[a.indices.fill_null(-1).to_numpy()])
    return np.concatenate(out) if out else np.zeros(0, object)


def road_columns(states: pa.Table) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(road_id, lane_id, road_s, on)`` per states row: the road ids (object array, None where
    null), the lane ids and ``road_s`` (float, NaN where null) and ``on``, the rows on a road (a
    road id with a finite lane id and ``road_s``)."""
    road = string_values(states, "road_id")
    lane = column_numpy(states, "lane_id", missing=np.nan)
    rs = column_numpy(states, "road_s", missing=np.nan)
    on = np.array([r is not None for r in road], dtype=bool) & np.isfinite(lane) & np.isfinite(rs)
    return road, lane, rs, on


# --- segments and ragged indices ------------------------------------------------------------------

def segments(pid: np.ndarray, t: np.ndarray, max_gap: float) -> tuple[np.ndarray, np.ndarray]:
    """``(start, length)`` of the track segments of rows sorted by (participant, time): a new
    segment starts at a new participant or after a gap longer than ``max_gap``."""
    n = len(t)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    brk = np.ones(n, bool)
    brk[1:] = (pid[1:] != pid[:-1]) | (np.diff(t) > max_gap)
    start = np.flatnonzero(brk)
    length = np.diff(np.r_[start, n])
    return start, length


def ragged(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(segment, position)`` of every element of segments of the given lengths, concatenated."""
    lengths = np.asarray(lengths, np.int64)
    seg = np.repeat(np.arange(len(lengths)), lengths)
    first = np.cumsum(lengths) - lengths
    return seg, np.arange(int(lengths.sum())) - first[seg]


def find_rows(pid_s: np.ndarray, t_s: np.ndarray, pid: np.ndarray, t: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """For each ``(pid, t)``: its position among the rows ``(pid_s, t_s)`` (sorted by participant,
    then time; clipped to them) and whether it is there. One integer key per row from the ranks
    of participant and time (``searchsorted`` on record arrays compares field by field in Python
    objects: ~20x slower)."""
    n = len(pid_s)
    if not n or not len(pid):
        return np.zeros(len(pid), np.int64), np.zeros(len(pid), bool)
    up = pid_s[np.r_[True, pid_s[1:] != pid_s[:-1]]]
    ut = np.unique(t_s)

    def rank(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r = np.minimum(np.searchsorted(u, v), len(u) - 1)
        return r, u[r] == v

    ps, _ = rank(up, pid_s)
    ts_, _ = rank(ut, t_s)
    pq_, pin = rank(up, pid)
    tq, tin = rank(ut, t)
    ks = ps * len(ut) + ts_
    kq = pq_ * len(ut) + tq
    pos = np.minimum(np.searchsorted(ks, kq), n - 1)
    return pos, pin & tin & (ks[pos] == kq)


def searchsorted_segments(a: np.ndarray, lo: np.ndarray, hi: np.ndarray, v: np.ndarray
                          ) -> np.ndarray:
    """For each query, ``searchsorted(a[lo:hi], v)`` (vectorised bisection)."""
    left = lo.copy()
    right = hi.copy()
    while True:
        active = left < right
        if not active.any():
            break
        mid = (left + right) // 2
        go = active & (a[np.minimum(mid, len(a) - 1)] < v)
        left = np.where(go, mid + 1, left)
        right = np.where(active & ~go, mid, right)
    return left - lo
