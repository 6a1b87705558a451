"""The object rows of the one pass (:func:`~aveas_format.converters.ros2_mcap.read.read_topics`)
flushed every :data:`FLUSH_ROWS` rows as columns into a
:class:`~aveas_format.io.resort.StatesWriter` keyed by an integer track code (``track``: 1.. in
the order the tracks first appear; 0 is the ego's), and what the import decides over all rows
before it makes states of any: each row's stamp and frame (small: 12 bytes a row), the frames'
first rows and the first non-finite pose (to name the same message as an error would)."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from aveas_format.converters.ros2_mcap.messages import ObjectRows
from aveas_format.converters.ros2_mcap.options import NCLS
from aveas_format.io.arrow import column_numpy
from aveas_format.io.resort import StatesWriter

#: object rows decoded (Python lists) before they are flushed into the writer as columns
FLUSH_ROWS = 65_536
#: bytes of object rows an import in bounded memory holds before it spills: a row is ~430 bytes
#: (poses, covariances, class PMF) and making a bucket's states costs ~8 times its bytes, so a
#: quarter of :data:`~aveas_format.io.resort.IMPORT_MEMORY` (an import held whole peaks near 0.5 GB)
MEMORY = 32 << 20
#: the per-row blocks, stored as numbered float64 columns (``pose0``..``pose6``...): name -> width
BLOCKS = {"pose": 7, "pcov": 9, "twist": 3, "tcov": 9, "dims": 3, "pmf": NCLS}
#: the integer columns of a row (its track code, stamp, topic index, frame code, twist kind,
#: orientation availability, message and object index)
INTS = ("track", "t_ns", "topic", "frame", "kind", "orient", "mi", "oi")


class ObjectSink:
    """:class:`ObjectRows` filled by the per-message readers (``rows``), flushed into ``writer``
    every :data:`FLUSH_ROWS` rows. ``multi_topic``: the track key is ``"topic:id"`` (else the
    object id)."""

    def __init__(self, writer: StatesWriter, multi_topic: bool) -> None:
        self.writer, self.multi = writer, multi_topic
        self.rows = ObjectRows()
        self.code_of: dict[str, int] = {}
        self.keys: list[str] = []          # the key of track code 1, 2...
        self.frame_of: dict[str, int] = {}
        self.frames: list[str] = []        # frame code -> frame_id
        self.frame_first: list[tuple[int, int]] = []  # frame code -> (topic, message) of its first row
        self.t_ns: list[np.ndarray] = []
        self.fcode: list[np.ndarray] = []
        self.track: list[np.ndarray] = []
        self.bad: tuple[int, int, int] | None = None  # the first non-finite pose: topic, message, object

    def maybe_flush(self) -> None:
        if len(self.rows.t_ns) >= FLUSH_ROWS:
            self.flush()

    def flush(self) -> None:
        r = self.rows
        n = len(r.t_ns)
        if not n:
            return
        self.rows = ObjectRows()
        t_ns = np.asarray(r.t_ns, np.int64)
        topic = np.asarray(r.topic, np.int64)
        where = np.asarray(r.where, np.int64).reshape(n, 2)
        blocks = {k: np.asarray(getattr(r, k), np.float64).reshape(n, w) for k, w in BLOCKS.items()}
        if self.bad is None:
            bad = ~np.isfinite(blocks["pose"]).all(axis=1)
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                self.bad = (int(topic[i]), int(where[i, 0]), int(where[i, 1]))
        frames, first, inv = np.unique(np.asarray(r.frame, dtype=object).astype(str), return_index=True,
                                       return_inverse=True)
        glob = np.empty(len(frames), np.int64)
        for j, fr in enumerate(frames.tolist()):  # (a few frames)
            g = self.frame_of.get(fr)
            if g is None:
                g = self.frame_of[fr] = len(self.frames)
                self.frames.append(fr)
                self.frame_first.append((int(topic[first[j]]), int(where[first[j], 0])))
            glob[j] = g
        fcode = glob[inv.reshape(-1)]
        oid = pa.array(r.oid, pa.string())
        keys = pc.binary_join_element_wise(pa.array(topic).cast(pa.string()), oid, ":") if self.multi else oid
        enc = pc.dictionary_encode(keys)  # (uniques in the order of first appearance)
        codes = np.empty(len(enc.dictionary), np.int64)
        for j, k in enumerate(enc.dictionary.to_pylist()):  # (a track at a time)
            c = self.code_of.get(k)
            if c is None:
                self.keys.append(k)
                c = self.code_of[k] = len(self.keys)
            codes[j] = c
        track = codes[enc.indices.to_numpy()]
        self.t_ns.append(t_ns)
        self.fcode.append(fcode.astype(np.int32))
        self.track.append(track)
        cols = {"track": track, "t_ns": t_ns, "topic": topic, "frame": fcode,
                "kind": np.asarray(r.twist_kind, np.int64), "orient": np.asarray(r.orient, np.int64),
                "mi": where[:, 0], "oi": where[:, 1], "nru": np.asarray(r.nru, np.float64),
                "nru_label": pa.array(r.nru_label, pa.string())}
        for k, a in blocks.items():
            cols.update({f"{k}{j}": np.ascontiguousarray(a[:, j]) for j in range(a.shape[1])})
        self.writer.add(cols)

    def columns(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every row's stamp, frame code and track code (after the last flush)."""
        self.flush()
        cat = [np.concatenate(a) if a else np.zeros(0, t) for a, t in
               ((self.t_ns, np.int64), (self.fcode, np.int32), (self.track, np.int64))]
        self.t_ns, self.fcode, self.track = [], [], []
        return cat[0], cat[1], cat[2]


def block(t: pa.Table, name: str) -> np.ndarray:
    """A per-row block (:data:`BLOCKS`) of a bucket's rows, (n, width) float64."""
    w = BLOCKS[name]
    out = np.empty((t.num_rows, w))
    for j in range(w):
        out[:, j] = column_numpy(t, f"{name}{j}")
    return out


def ints(t: pa.Table, name: str) -> np.ndarray:
    return np.asarray(t.column(name).to_numpy(), np.int64)
