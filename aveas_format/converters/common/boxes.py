"""What a converter hands to the shared step (:func:`~aveas_format.converters.common.assemble.
to_recording`): **box batches** and the **sensor description**.

:class:`Boxes` holds one row per box (a participant at a time) in any order, as columns: the
participant (a code 0..m-1 and the source id of each code), the time (s), the footprint centre
x/y in the map's local frame and whatever else the source has of the states table (heading,
velocity, their ``_std``/``_corr``, ``z``, accelerations, lights, ``source_frame``...), plus the
per-box measurements the shared step aggregates per participant: ``length``, ``width``,
``height`` (m) and ``class_pmf`` (one row of 13 probabilities per box), and for a sensor with a
range, where it stood at each box (``sensor_pose``: x, y, z, yaw). Where each row came from
(:class:`Rows`: file, CSV line or message index) locates what the shared step reports. The
duplicates policy — what a second sample of a participant at the same time means — is declared
with the boxes: ``"error"`` (a located :class:`~aveas_format.errors.FormatError` naming the file,
the place of the repeat and the participant) or ``"first"`` (the first is kept, one warning
naming the file, the count and an example participant).

:class:`Sensor` describes the acquisition: what recording.json's ``acquisition`` says (method,
platform, sensors, what is not observable, the site), provenance, the source's defaults for
partner and start time, the recording's CRS where the source fixes it, the coverage
(:class:`Footprint`: an aerial view's ground footprint; :class:`Range`: a sensor with a range and
field of view, possibly moving, with the ground shadows of the boxes) and how sizes measured box
by box become a participant's (:class:`Sizes`).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from aveas_format.errors import FormatError
from aveas_format.numeric import fmt_num
from aveas_format.schema.tables import TABLES

#: per-box columns that are no states column: aggregated per participant or used for coverage
MEASURED = ("length", "width", "height", "class_pmf", "sensor_pose")
#: the states columns a box batch may carry (the key, time, x, y are given apart)
STATE_COLUMNS = tuple(c.name for c in TABLES["states"].columns
                      if c.name not in ("participant_id", "time", "x", "y"))
Duplicates = Literal["error", "first"]


@dataclass(frozen=True)
class Rows:
    """Where each box came from: the input ``files``, the index into them of each row (``file``;
    None: all in the first) and its place there (``place``: a CSV line, a message or frame
    index...; None: unknown), counted in ``unit`` (the keyword of the error's location: ``line``,
    ``frame``, ``row``, ``message``)."""

    files: Sequence[Path]
    file: np.ndarray | None = None
    place: np.ndarray | None = None
    unit: str = "line"

    def path(self, i: int) -> Path | None:
        if not self.files:
            return None
        return Path(self.files[0 if self.file is None else int(self.file[i])])

    def locate(self, i: int) -> dict[str, Any]:
        """The error location of row ``i``: the file and the place in it (where known)."""
        place = None if self.place is None else self.place[i]
        known = place is not None and not (isinstance(place, float) and np.isnan(place))
        return {"path": self.path(i), self.unit: int(place) if known else None}

    def take(self, idx: np.ndarray) -> Rows:
        return Rows(self.files, None if self.file is None else np.asarray(self.file)[idx],
                    None if self.place is None else np.asarray(self.place)[idx], self.unit)


class Boxes:
    """A batch of boxes as columns (see the module doc).

    ``pid``: each row's participant code 0..m-1; ``source_ids``: the source's id of each code
    (``source_ids[code]``); ``time`` (s); ``x``, ``y`` the footprint centre in the map's local
    frame; further columns by name: a states column (:data:`STATE_COLUMNS`) or one of
    :data:`MEASURED`. ``rows`` says where each row came from; ``duplicates`` the policy.
    """

    def __init__(self, pid: Any, time: Any, x: Any, y: Any, *, source_ids: Sequence[Any],
                 rows: Rows | None = None, duplicates: Duplicates = "error", **columns: Any) -> None:
        unknown = sorted(set(columns) - set(STATE_COLUMNS) - set(MEASURED))
        if unknown:
            raise ValueError(f"Boxes: unknown column(s) {unknown}: a states column or one of "
                             f"{list(MEASURED)}")
        if duplicates not in ("error", "first"):
            raise ValueError(f"Boxes: duplicates must be 'error' or 'first', not {duplicates!r}")
        self.pid = np.asarray(pid, np.int64)
        self.time = np.asarray(time, np.float64)
        self.source_ids = np.asarray(list(source_ids), dtype=object)
        self.rows = rows
        self.duplicates: Duplicates = duplicates
        self.columns: dict[str, Any] = {"x": np.asarray(x, np.float64),
                                        "y": np.asarray(y, np.float64)}
        self.columns.update({k: v for k, v in columns.items() if v is not None})
        n = len(self.pid)
        for k, v in (("time", self.time), *self.columns.items()):
            if len(v) != n:
                raise ValueError(f"Boxes: column {k!r} has {len(v)} rows, pid {n}")
        #: each row's index in the batch as it was made (kept through sorting and dropping)
        self.order = np.arange(n)
        self.is_sorted = False

    # -- columns -----------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.pid)

    @property
    def m(self) -> int:
        """Number of participants (codes 0..m-1)."""
        return len(self.source_ids)

    def __contains__(self, name: str) -> bool:
        return name in self.columns

    def __getitem__(self, name: str) -> Any:
        return self.columns[name]

    def __setitem__(self, name: str, values: Any) -> None:
        if name not in STATE_COLUMNS and name not in MEASURED and name not in ("x", "y"):
            raise ValueError(f"Boxes: unknown column {name!r}")
        if len(values) != len(self):
            raise ValueError(f"Boxes: column {name!r} has {len(values)} rows, not {len(self)}")
        self.columns[name] = values

    def get(self, name: str, default: Any = None) -> Any:
        return self.columns.get(name, default)

    def take(self, idx: np.ndarray) -> Boxes:
        """The rows ``idx`` (in that order), every column and the rows' origin with them."""
        out = object.__new__(Boxes)
        out.pid, out.time = self.pid[idx], self.time[idx]
        out.source_ids, out.duplicates = self.source_ids, self.duplicates
        out.rows = None if self.rows is None else self.rows.take(idx)
        out.columns = {k: _take(v, idx) for k, v in self.columns.items()}
        out.order = self.order[idx]
        out.is_sorted = False
        return out

    # -- the one sort ----------------------------------------------------------------------------
    def sort(self, repeats: list | None = None) -> Boxes:
        """The rows sorted by (participant, time) with the duplicates policy applied: ``error``
        raises naming the later of two samples of a participant at one time (its file and place)
        and the participant's source id; ``first`` keeps the first (in the batch's order) and
        warns once with the count (:func:`repeat_message`), or, given a list ``repeats``, appends
        ``(count, path, who, time)`` of the first repeat to it instead (a source that sorts its
        boxes a bucket at a time warns once for all). Sorted boxes are returned as they are."""
        if self.is_sorted:
            return self
        order = np.lexsort((self.time, self.pid))
        ps, ts = self.pid[order], self.time[order]
        dup = np.zeros(len(ps), bool)  # (no rows: none)
        dup[1:] = (ps[1:] == ps[:-1]) & (ts[1:] == ts[:-1])
        if dup.any():
            k = int(np.flatnonzero(dup)[0])
            i = int(order[k])  # the later sample (lexsort is stable)
            who = f"participant {str(self.source_ids[int(self.pid[i])])!r}"
            where = self.rows.locate(i) if self.rows is not None else {}
            if self.duplicates == "error":
                raise FormatError(f"{who} sampled twice at time {fmt_num(self.time[i])}", **where)
            path = where.get("path")
            if repeats is not None:
                repeats.append((int(dup.sum()), path, who, float(self.time[i])))
            else:
                warnings.warn(repeat_message(int(dup.sum()), path, who, float(self.time[i])),
                              stacklevel=3)
        out = self.take(order[~dup])
        out.is_sorted = True
        return out

    def drop_participants(self, drop: np.ndarray) -> Boxes:
        """The boxes without the participants whose code ``drop`` (a mask over the codes) marks;
        the others renumbered 0.. in their order (a source's filter of whole tracks)."""
        drop = np.asarray(drop, bool)
        if not drop.any():
            return self
        out = self.take(np.flatnonzero(~drop[self.pid]))
        out.pid = (np.cumsum(~drop) - 1)[out.pid]
        out.source_ids = self.source_ids[~drop]
        out.is_sorted = self.is_sorted
        return out

    # -- per participant (sorted boxes) ----------------------------------------------------------------
    def first_rows(self) -> np.ndarray:
        """The first row of each participant that has rows (sorted boxes: its earliest)."""
        return np.unique(self.pid, return_index=True)[1]

    def counts(self) -> np.ndarray:
        """Rows per participant code (0 for a participant without rows)."""
        return np.bincount(self.pid, minlength=self.m)


def repeat_message(count: int, path: Path | None, who: str, time: float) -> str:
    """The warning of the duplicates policy ``first``: ``count`` samples dropped, the first
    repeat (``who`` at ``time`` s) as the example."""
    return (f"{path.name + ': ' if path else ''}{count} sample(s) repeat a participant's time and "
            f"were dropped, the first kept (e.g. {who} at time {fmt_num(time)} s)")


def _take(v: Any, idx: np.ndarray) -> Any:
    if isinstance(v, np.ndarray):
        return v[idx]
    if hasattr(v, "take"):  # a pyarrow array
        return v.take(idx)
    return np.asarray(v, dtype=object)[idx] if isinstance(v, list) else np.asarray(v)[idx]


# --- the sensor description ----------------------------------------------------------------------

@dataclass(frozen=True)
class Footprint:
    """An aerial view's ground footprint (WKT polygon in the local frame), fixed for the
    recording: the recording's ``coverage``; the map's surroundings outside it are one
    ``outside_coverage`` region of ``unobserved`` for the whole recording. Occlusions (bridges,
    trees) are not known to such sources and not claimed."""

    wkt: str
    sensor_id: str


@dataclass(frozen=True)
class Range:
    """A sensor with a range and a horizontal field of view (LiDAR, a camera with a ground
    footprint), standing where the boxes' ``sensor_pose`` column says (x, y, z, yaw of the field
    of view's centre, per box; a sensor that moves gets its unobserved regions frame by frame) or
    at ``pose`` for the whole recording. Outside ``range_m`` the map's surroundings are
    ``sensor_range``, inside it but outside ``fov`` (rad) or ``observed`` (a shapely polygon, e.g.
    a camera's ground footprint) ``field_of_view``; with ``occlusion`` every box casts its ground
    shadow seen from the sensor (``occlusion`` regions with ``occluder_id``; a box without height
    counts as ``default_height`` m tall). ``period``: the frame period, which ends the last frame
    (the recording's duration)."""

    sensor_id: str
    range_m: float
    period: float
    fov: float = 2 * np.pi
    pose: tuple[float, float, float, float] | None = None
    observed: Any = None
    occlusion: bool = False
    default_height: float = 1.5


@dataclass(frozen=True)
class Sizes:
    """How the sizes measured box by box (the boxes' ``length``/``width``/``height``) become a
    participant's: their ``statistic`` (mean, or median: robust to a detector's outliers), and
    as ``*_std`` their spread over the track (sample standard deviation), at least ``floor`` m
    (None: no floor; a participant with one box then has an unknown std)."""

    statistic: Literal["mean", "median"] = "mean"
    floor: float | None = None


@dataclass(frozen=True)
class Sensor:
    """How the boxes were acquired (see the module doc): ``method`` (acquisition.method),
    ``platform`` and ``sensors`` (acquisition.sensors entries), ``provenance`` of the recording,
    ``partner``/``start_time`` and the rights (``license``, ``owner``, ``right_of_use``; None: not
    stated) as the source states them (the import options given override them),
    ``not_observable`` and ``site`` (acquisition), ``crs`` (the recording's CRS where the source
    fixes the frame and the map has no geoReference), ``coverage``, ``sizes``,
    ``nominal_rate_hz``/``duration_s`` where the source states them, ``title``, and ``extras``
    (recording.json ``extras``: what the source states that has no field)."""

    method: str
    platform: str
    sensors: Sequence[Mapping[str, Any]] = ()
    provenance: str = "natural"
    partner: str = "unknown"
    start_time: str = "1970-01-01T00:00:00Z"
    not_observable: Sequence[str] | None = None
    site: Mapping[str, Any] | None = None
    crs: str | None = None
    coverage: Footprint | Range | None = None
    sizes: Sizes = field(default_factory=Sizes)
    nominal_rate_hz: float | None = None
    duration_s: float | None = None
    title: str | None = None
    extras: Mapping[str, Any] | None = None
    license: str | None = None
    owner: str | None = None
    right_of_use: str | None = None

    def acquisition(self) -> dict[str, Any]:
        out: dict[str, Any] = {"platform": self.platform, "sensors": [dict(s) for s in self.sensors]}
        if self.not_observable is not None:
            out["not_observable"] = list(self.not_observable)
        if self.site is not None:
            out["site"] = dict(self.site)
        return out
