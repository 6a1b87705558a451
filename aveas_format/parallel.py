"""One place that maps work over recordings or simulations: in-process, local processes, or an
existing Dask cluster.

>>> from aveas_format.parallel import run_tasks
>>> for r in run_tasks(validate_one, paths, workers=4):          # or scheduler="tcp://host:8786"
...     print(r.item, r.error or r.value)

Results stream back as tasks finish (not in input order; ``TaskResult.index`` gives the position).
A task that raises, or whose worker process dies (segfault, ``os._exit``, out of memory), becomes a
``TaskResult`` with ``error`` set, and the other tasks still complete: a broken local pool is
replaced and its in-flight tasks are retried one at a time to find the one that killed it.
"""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any


@dataclass
class TaskResult:
    """The outcome of one task."""

    index: int
    item: Any
    value: Any = None
    error: str | None = None
    traceback: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def _call(fn: Callable[[Any], Any], item: Any) -> tuple[Any, str | None, str | None]:
    """Run one task, capturing its exception (runs inside the worker)."""
    try:
        return fn(item), None, None
    except Exception as e:  # noqa: BLE001 — a failing task is data for the caller
        return None, f"{type(e).__name__}: {e}", traceback.format_exc()


def default_workers() -> int:
    return max(1, (os.cpu_count() or 1))


def processes(workers: int | None) -> int:
    """How many processes ``workers`` means for :func:`map_ordered`: 0/None one per core, but 1
    in a worker process (no pool inside a pool's worker)."""
    if workers:
        return workers
    import multiprocessing

    return 1 if multiprocessing.parent_process() is not None else default_workers()


def background(fn: Callable[..., Any], *args: Any, name: str = "background") -> Future:
    """``fn(*args)`` started in a thread of its own; its Future (``result()`` waits, and raises
    what ``fn`` raised). For work that releases the GIL (hashing, PROJ, numpy, Arrow) overlapped
    with other work of this process: the one home of such threads."""
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
    try:
        return pool.submit(fn, *args)
    finally:
        pool.shutdown(wait=False)


def read_ahead(fn: Callable[[Any], Any], items: Iterable[Any]) -> Iterator[Any]:
    """``fn(item)`` for each item, in order, the next one's made in a thread (:func:`background`)
    while the caller works on this one: for reading that releases the GIL (Parquet row groups,
    Arrow IPC) overlapped with what is done with what was read. One ``fn`` runs at a time (a
    reader need not be thread-safe, only usable from another thread). An exception of ``fn`` is
    raised at its item; closed early, the read in flight is waited for (no thread left behind)."""
    it = iter(items)
    fut: Future | None = None
    try:
        for item in it:
            got = fut.result() if fut is not None else None  # (one read at a time: the one before
            first = fut is None                              # done before the next begins)
            fut = background(fn, item, name="read-ahead")
            if not first:
                yield got
        if fut is not None:
            got, fut = fut.result(), None
            yield got
    finally:
        if fut is not None:  # (the caller stopped, or an item failed: the read in flight finished)
            try:
                fut.result()
            except BaseException:  # noqa: BLE001 - not the caller's error: it never asked for it
                pass


def run_tasks(fn: Callable[[Any], Any], items: Iterable[Any], *, workers: int | None = 1,
              scheduler: str | None = None, progress: bool = False, description: str = "tasks"
              ) -> Iterator[TaskResult]:
    """Run ``fn(item)`` for every item; yield a :class:`TaskResult` per item as it finishes.

    workers: 1 = in this process (default), N > 1 = N local processes, 0/None = one per core.
    scheduler: address of an existing Dask scheduler (``tcp://host:8786``); overrides workers.
    ``fn`` must be picklable (a module-level function) for processes and Dask.
    """
    items = list(items)
    bar = Progress(len(items), description) if progress else None
    try:
        if scheduler:
            gen = _run_dask(fn, items, scheduler)
        elif workers == 1 or len(items) <= 1:
            gen = (TaskResult(i, it, *_call(fn, it)) for i, it in enumerate(items))
        else:
            gen = _run_processes(fn, items, workers or default_workers())
        for r in gen:
            if bar:
                bar.advance(r.ok)
            yield r
    finally:
        if bar:
            bar.close()


def _run_processes(fn: Callable[[Any], Any], items: list[Any], workers: int) -> Iterator[TaskResult]:
    pending = list(range(len(items)))[::-1]  # a stack of indices still to submit
    suspects: list[int] = []  # in flight when a pool broke: retried one at a time
    while pending or suspects:
        if suspects:
            i = suspects.pop()
            yield _run_isolated(fn, items, i)
            continue
        with ProcessPoolExecutor(max_workers=min(workers, len(pending))) as pool:
            running: dict[Future, int] = {}
            broken = False
            while (pending or running) and not broken:
                while pending and len(running) < 2 * workers:
                    i = pending.pop()
                    running[pool.submit(_call, fn, items[i])] = i
                done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                for fut in done:
                    i = running.pop(fut)
                    try:
                        value, err, tb = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        suspects.append(i)
                        continue
                    yield TaskResult(i, items[i], value, err, tb)
            if broken:
                suspects.extend(running.values())
                pool.shutdown(wait=False, cancel_futures=True)


def _run_isolated(fn: Callable[[Any], Any], items: list[Any], i: int) -> TaskResult:
    """Run one task in a fresh one-worker pool: a crash there is this task's."""
    with ProcessPoolExecutor(max_workers=1) as pool:
        try:
            value, err, tb = pool.submit(_call, fn, items[i]).result()
        except BrokenProcessPool:
            return TaskResult(i, items[i], None, "the worker process died (crash, os._exit or out of "
                              "memory) while running this task", None)
    return TaskResult(i, items[i], value, err, tb)


def _run_dask(fn: Callable[[Any], Any], items: list[Any], scheduler: str) -> Iterator[TaskResult]:
    from aveas_format.errors import require

    require("distributed", extra="dask", what="a Dask scheduler (--scheduler)")
    from distributed import Client, as_completed
    with Client(scheduler) as client:
        futures = client.map(_call, [fn] * len(items), items, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        suspects: list[int] = []  # KilledWorker: perhaps only queued on a worker another task killed
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                value, err, tb = fut.result()
            except Exception as e:  # noqa: BLE001 — e.g. KilledWorker: the task killed its workers
                if type(e).__name__ == "KilledWorker":
                    suspects.append(i)
                    continue
                value, err, tb = None, f"{type(e).__name__}: {e}", None
            yield TaskResult(i, items[i], value, err, tb)
        for i in sorted(suspects):  # retried one at a time: a crash now is this task's own
            fut = client.submit(_call, fn, items[i], pure=False)
            try:
                value, err, tb = fut.result()
            except Exception as e:  # noqa: BLE001
                value, err, tb = None, f"{type(e).__name__}: {e}", None
                if type(e).__name__ == "KilledWorker":
                    err = ("the worker process died (crash, os._exit or out of memory) while "
                           f"running this task ({err})")
            yield TaskResult(i, items[i], value, err, tb)


class Progress:
    """A rich progress bar on stderr (quiet when stderr is not a terminal): ``total`` steps (tasks,
    or bytes of a file read), with a count of the failed tasks where ``failures``."""

    def __init__(self, total: int, description: str, *, failures: bool = True) -> None:
        from rich.console import Console
        from rich.progress import (BarColumn, DownloadColumn, MofNCompleteColumn, Progress, TextColumn,
                                   TimeElapsedColumn)

        count = (MofNCompleteColumn(), TextColumn("{task.fields[failed]} failed")) if failures else (DownloadColumn(),)
        self._p = Progress(TextColumn("{task.description}"), BarColumn(), *count, TimeElapsedColumn(),
                           console=Console(file=sys.stderr), disable=not sys.stderr.isatty())
        self._p.start()
        self._task = self._p.add_task(description, total=total, failed=0)
        self._failed = 0

    def advance(self, ok: bool = True, steps: int = 1) -> None:
        self._failed += 0 if ok else 1
        self._p.update(self._task, advance=steps, failed=self._failed)

    def close(self) -> None:
        self._p.stop()


def map_ordered(fn: Callable[[Any], Any], items: Iterable[Any], *, workers: int | None = 1,
                ahead: int | None = None) -> Iterator[tuple[Any, Any]]:
    """``(item, fn(item))`` for each item of a lazy iterable, in input order, ``fn`` run in ``workers``
    local processes (1 = in this process; 0/None = one per core) with at most ``ahead`` in flight
    (default ``2 * workers``): memory stays bounded by what those items and results hold. Meant
    for the blocks of one large file (read, cut and sent by the caller, parsed by the workers).

    An exception in ``fn`` is raised here at that item's position (the remaining items are
    dropped). Where a worker process dies (crash, out of memory), that item and the ones after it
    run in this process. Closing the generator early cancels what is still in flight."""
    workers = processes(workers)
    if workers <= 1:
        for item in items:
            result = fn(item)
            yield item, result
            del item, result  # (not held while the next item is read and run)
        return
    ahead = max(1, ahead or 2 * workers)
    it = iter(items)
    pool = ProcessPoolExecutor(max_workers=workers)
    queue: list[tuple[Any, Future]] = []
    try:
        for item in it:
            queue.append((item, _submit(pool, fn, item)))
            if len(queue) < ahead:
                continue
            yield _take(fn, queue.pop(0))
        while queue:
            yield _take(fn, queue.pop(0))
    finally:
        for _, fut in queue:
            fut.cancel()
        pool.shutdown(wait=True, cancel_futures=True)


def _submit(pool: ProcessPoolExecutor, fn: Callable[[Any], Any], item: Any) -> Future:
    try:
        return pool.submit(fn, item)
    except BrokenProcessPool as e:  # (the pool broke earlier: the item runs here, in _take)
        fut: Future = Future()
        fut.set_exception(e)
        return fut


def _take(fn: Callable[[Any], Any], entry: tuple[Any, Future]) -> tuple[Any, Any]:
    item, fut = entry
    try:
        return item, fut.result()
    except BrokenProcessPool:  # a worker died: this item (and, via their futures, the later ones) here
        return item, fn(item)
