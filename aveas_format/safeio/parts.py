"""One file's content encoded in parts by forked processes, copied into the output as it grows.

A streamed export whose content is a sequence of chunks — ``encode(part=(first, end))`` yields
the bytes of the chunks ``[first, end)``, the same bytes whether a process encodes them alone or
as part of the whole sequence — hands :class:`ForkedParts` the chunks' row offsets and gets back, from
:meth:`ForkedParts.chunks`, what :func:`~aveas_format.safeio.atomic.write_chunks_atomic` writes:
this process's parts as bytes, each forked part as a
:class:`~aveas_format.safeio.atomic.GrowingSegment` of the file its process writes. The output
is byte-identical whatever the number of processes, and whatever processes fail.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from aveas_format.safeio.atomic import GrowingSegment

#: rows from which the chunks are encoded in parts by forked processes (below: the fork and the
#: copy cost more than they save)
PARTS_MIN_ROWS = 200_000

#: rows of one part (about 230 MB of the OpenLABEL export's JSON): small enough that a part's file
#: is copied into the output and removed before the kernel writes it back to the disk, large
#: enough that the processes seldom wait for each other
PART_ROWS = 200_000

#: a forked part handed on before this process settles the oldest one (the writer's queue holds
#: more: the producer never waits on a full queue while the writer waits for it)
MAX_PENDING = 2


class ForkedParts:
    """The chunks of ``encode`` (``bounds``: their row offsets, the number of rows last) in parts
    of about :data:`PART_ROWS` rows, dealt round by round (:func:`deal_parts`) to this process and
    ``workers - 1`` processes forked when this object is made (they inherit what ``encode``
    reads: make it before any thread of the writer starts); the last part is this process's.

    :meth:`chunks` streams this process's parts and hands each forked part on as a
    :class:`~aveas_format.safeio.atomic.GrowingSegment` of the file its process writes in
    ``spill_dir`` (named ``prefix``...; the writer copies it as it grows, while this process
    encodes its next part; a part's file is removed once copied, so the files never add up to the
    output's size). Before the first chunk of its next part this process *settles* the forked
    parts handed on: waits for their processes' word that each is whole (or that the process
    died: the part is then cut off the output and encoded here, and so are that process's later
    parts). Each word carries ``state()`` of the process so far (what its encoding accumulated),
    given to ``merge`` at the end. Where fork is not available or the rows are fewer than
    :data:`PARTS_MIN_ROWS`, everything is encoded here. :meth:`close` stops what still runs and
    removes its files."""

    def __init__(self, encode: Callable[..., Iterable[bytes]], bounds: Sequence[int],
                 workers: int, spill_dir: Path, *, state: Callable[[], Any] | None = None,
                 merge: Callable[[Any], None] | None = None, prefix: str = ".parts.") -> None:
        import multiprocessing
        import tempfile

        self.encode, self.state, self.merge = encode, state or (lambda: None), merge
        self.procs: dict[int, Any] = {}  # owner -> (process, its end of the pipe)
        self.files: dict[int, Path] = {}  # part -> the file its process writes
        self.states: dict[int, Any] = {}  # owner -> its last word's state
        self.done: dict[int, int] = {}  # owner -> the parts it has reported whole
        self.failed: set[int] = set()
        self.parts = deal_parts(list(bounds), workers)
        if (bounds[-1] < PARTS_MIN_ROWS or len(self.parts) < 2
                or "fork" not in multiprocessing.get_all_start_methods()):
            self.parts = [(0, len(bounds) - 1, 0)]
            return
        ctx = multiprocessing.get_context("fork")
        try:
            for owner in range(1, workers):
                mine = [j for j, (_, _, o) in enumerate(self.parts) if o == owner]
                for j in mine:
                    fd, name = tempfile.mkstemp(prefix=prefix, suffix=".tmp", dir=spill_dir)
                    os.close(fd)
                    self.files[j] = Path(name)
                rd, wr = ctx.Pipe(duplex=False)
                proc = ctx.Process(target=_write_parts, daemon=True,
                                   args=(encode, self.state,
                                         [(j, self.parts[j][:2], str(self.files[j])) for j in mine], wr))
                proc.start()
                wr.close()
                self.procs[owner] = (proc, rd)
                self.done[owner] = -1
        except BaseException:
            self.close()
            raise

    def _here(self, j: int) -> Iterable[bytes]:
        return self.encode(part=self.parts[j][:2])

    def _whole(self, owner: int, j: int) -> bool:
        """Whether the process ``owner`` wrote its part ``j`` whole (waits for its word)."""
        proc, rd = self.procs[owner]
        while owner not in self.failed and self.done[owner] < j:
            try:
                self.done[owner], self.states[owner] = rd.recv()
            except EOFError:  # (the process died)
                proc.join()
                self.failed.add(owner)
        return self.done[owner] >= j

    def _settle(self, pending: list) -> Iterator[bytes]:
        """The forked parts handed on, settled in order: finished, or cut off and encoded here."""
        while pending:
            seg, j = pending[0]
            ok = False
            try:
                ok = self._whole(self.parts[j][2], j)
            finally:
                seg.finish(ok)  # (the writer cuts off what it copied of a part not whole)
                pending.pop(0)
            if not ok:  # here, with the real error if there is one
                yield from self._here(j)

    def chunks(self) -> Iterator[Any]:
        pending: list = []  # (segment, part) handed on, not yet settled
        try:
            for j, (_, _, owner) in enumerate(self.parts):
                if owner and owner not in self.failed:
                    if len(pending) >= MAX_PENDING:
                        yield from self._settle(pending[:1])
                        pending.pop(0)
                    pending.append((GrowingSegment(self.files.pop(j)), j))
                    yield pending[-1][0]  # (copied while its process still writes it)
                    continue
                for chunk in self._here(j):
                    yield from self._settle(pending)  # (before this part's first chunk)
                    yield chunk
            yield from self._settle(pending)
        finally:
            for seg, _ in pending:  # (stopped early: the writer must not wait for them)
                seg.finish(False)
        for owner, (proc, _) in self.procs.items():
            proc.join()
            if owner in self.states and self.merge is not None:
                self.merge(self.states[owner])
        self.procs = {}

    def close(self) -> None:
        for proc, rd in self.procs.values():
            proc.kill()
            proc.join()
            rd.close()
        for spill in self.files.values():
            spill.unlink(missing_ok=True)
        self.procs, self.files = {}, {}


def deal_parts(bounds: list[int], workers: int) -> list[tuple[int, int, int]]:
    """The parts ``(first chunk, end chunk, owner)`` of :class:`ForkedParts` for the chunks' row
    offsets ``bounds``: rounds of one part per process (owner 0: this process), then a last part
    of this process's; about :data:`PART_ROWS` rows each, all about equal (a smaller share for
    this process, which also writes the output, was slower: docs/performance.md). Empty parts are
    left out; one part (owner 0) where the chunks are too few to share."""
    k, rows = len(bounds) - 1, bounds[-1]
    if workers < 2 or k < 2 * workers:
        return [(0, k, 0)]
    rounds = max(1, min(round(rows / (PART_ROWS * workers)), (k - 1) // workers))
    owners = [*(j % workers for j in range(rounds * workers)), 0]
    at = np.arange(1, len(owners)) / len(owners) * rows
    cuts = [0, *np.searchsorted(bounds, at).tolist(), k]
    return [(a, b, o) for a, b, o in zip(cuts[:-1], cuts[1:], owners) if b > a]


def _write_parts(encode: Callable[..., Iterable[bytes]], state: Callable[[], Any],
                 parts: list, conn) -> None:
    """A forked process of :class:`ForkedParts`: each of its ``parts`` (index, (first chunk, end
    chunk), file) into its file, then its word sent — the index and ``state()`` (nothing more
    sent: it failed)."""
    import gc

    gc.disable()  # (an encoder's millions of acyclic small objects: nothing for the collector)
    try:
        for j, part, spill in parts:
            with open(spill, "wb") as f:
                for data in encode(part=part):
                    f.write(data)
            conn.send((j, state()))
    finally:
        conn.close()


__all__ = ["MAX_PENDING", "PARTS_MIN_ROWS", "PART_ROWS", "ForkedParts", "deal_parts"]
