"""Atomic writes of single files: a temporary sibling, fsync, then rename."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterable
from pathlib import Path

from aveas_format.errors import RecordingIOError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary sibling and a rename (mode as for a new file
    under the current umask, not mkstemp's 0600)."""
    return write_chunks_atomic(path, (data,))


def write_chunks_atomic(path: str | Path, chunks: Iterable[bytes]) -> Path:
    """Write the byte chunks (or :class:`FileSegment` s) one after the other to ``path`` through a
    temporary sibling and a rename (a streamed export never holds the whole file); nothing is left
    behind when the iterator raises. A directory that is missing or not writable is a
    :class:`~aveas_format.errors.RecordingIOError` naming ``path`` and the directory (not the
    temporary file)."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=parent)
    except FileNotFoundError:
        raise RecordingIOError(f"cannot write: the directory {parent} does not exist",
                               path=path) from None
    except NotADirectoryError:
        raise RecordingIOError(f"cannot write: {parent} is not a directory", path=path) from None
    except PermissionError:
        raise RecordingIOError(f"cannot write: permission denied in the directory {parent}",
                               path=path) from None
    try:
        os.fchmod(fd, 0o666 & ~_umask())
        with os.fdopen(fd, "wb") as f:
            _write_behind(f, chunks)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


#: bytes written between two ``fdatasync`` of the writing thread (the disk writes back while the
#: chunks are still being made; the last ``fsync`` has only the rest left)
SYNC_EVERY = 256 << 20


#: bytes copied by one ``copy_file_range`` call of a :class:`FileSegment` (the syncs of the
#: writing thread come between two of them)
COPY_STEP = 64 << 20


class FileSegment:
    """A chunk of :func:`write_chunks_atomic` given as a file (written by another process): its
    bytes are copied into the output by the kernel (``os.copy_file_range``) and the file removed."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)

    def copy_into(self, f, wrote=None) -> int:
        """Append the file to the open output ``f`` (flushed first); the number of bytes.
        ``wrote(n)`` is told each step's bytes (the writer's syncs)."""
        f.flush()
        try:
            with open(self.path, "rb") as src:
                size = os.fstat(src.fileno()).st_size
                _copy_range(src.fileno(), f, 0, size, wrote, self.path)
        finally:
            self.discard()
        return size

    def discard(self) -> None:
        self.path.unlink(missing_ok=True)


class GrowingSegment(FileSegment):
    """A :class:`FileSegment` whose file another process is still appending to: copied as it
    grows (the copying overlaps that process's work instead of following it). The producer calls
    :meth:`finish` when the process is done: ``ok`` -> the rest copied; not ``ok`` -> what was
    copied of it is cut off the output again (truncated back to where the segment began), so
    that the producer can put the same bytes there another way. The file is removed either way."""

    #: seconds between two looks at the file while nothing new has come
    POLL = 0.01

    def __init__(self, path: str | Path) -> None:
        import threading

        super().__init__(path)
        self._done = threading.Event()
        self._ok = False

    def finish(self, ok: bool) -> None:
        """The writing process is done; ``ok``: the file is whole."""
        self._ok = ok
        self._done.set()

    def copy_into(self, f, wrote=None) -> int:
        f.flush()
        start = f.tell()
        done = 0
        try:
            with open(self.path, "rb") as src:
                while True:
                    finished = self._done.is_set()  # (before the size: all is in once it is set)
                    if finished and not self._ok:
                        f.truncate(start)
                        f.seek(start)
                        return 0
                    size = os.fstat(src.fileno()).st_size  # (bytes below it are written for good)
                    if size > done:
                        _copy_range(src.fileno(), f, done, size - done, wrote, self.path)
                        done = size
                    elif finished:
                        return done
                    else:
                        self._done.wait(self.POLL)
        finally:
            self.discard()


def _copy_range(src: int, f, offset: int, count: int, wrote=None, name: Path | None = None) -> None:
    """Append ``count`` bytes of the open file descriptor ``src`` (the file ``name``) from
    ``offset`` to the open (flushed) output ``f``: by the kernel where it can
    (``os.copy_file_range``), else read and written here."""
    end = offset + count
    while offset < end:
        n = 0
        try:
            n = os.copy_file_range(src, f.fileno(), min(end - offset, COPY_STEP), offset)
        except (AttributeError, OSError):  # (no copy_file_range here, or not between these files)
            pass
        if n == 0:  # (through Python: an error of the output is then raised as it is)
            data = os.pread(src, min(end - offset, 8 << 20), offset)
            if not data:
                raise RecordingIOError(f"the file ended {end - offset} bytes early", path=name)
            n = f.write(data)
            f.flush()
        offset += n
        if wrote is not None:
            wrote(n)


def _write_behind(f, chunks: Iterable[bytes]) -> None:
    """Write ``chunks`` to ``f`` in a thread while the caller's iterator makes the next ones (the
    writes and syncs release the GIL: encoding and writing overlap). An error of either side is
    raised here, the other side stopped first."""
    import queue
    import threading

    it = iter(chunks)
    first = next(it, None)
    if first is None:
        return
    q: queue.Queue = queue.Queue(maxsize=4)
    failed: list[BaseException] = []

    pending = 0

    def wrote(n: int) -> None:
        nonlocal pending
        pending += n
        if pending >= SYNC_EVERY:
            f.flush()
            getattr(os, "fdatasync", os.fsync)(f.fileno())
            pending = 0

    def run() -> None:
        while (data := q.get()) is not None:
            if failed:
                if isinstance(data, FileSegment):
                    data.discard()
                continue  # (drain until the end marker)
            try:
                if isinstance(data, FileSegment):
                    data.copy_into(f, wrote)
                else:
                    wrote(f.write(data))
            except BaseException as e:  # noqa: BLE001 - raised in the caller's thread
                failed.append(e)
                if isinstance(data, FileSegment):
                    data.discard()

    t = threading.Thread(target=run, name="write-behind", daemon=True)
    t.start()
    try:
        q.put(first)
        for data in it:
            if failed:
                break
            q.put(data)
    finally:
        q.put(None)
        t.join()
    if failed:
        raise failed[0]


def write_text_atomic(path: str | Path, text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))


def save_figure_atomic(fig, path: str | Path, **kw) -> Path:
    """``fig.savefig`` into memory (format from the suffix, PNG by default), then an atomic write."""
    import io

    path = Path(path)
    buf = io.BytesIO()
    fig.savefig(buf, format=kw.pop("format", path.suffix.lstrip(".").lower() or "png"), **kw)
    return write_bytes_atomic(path, buf.getvalue())


def write_parquet_atomic(table, path: str | Path, **kw) -> Path:
    """A pyarrow Table as Parquet, written atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, **kw)
    return write_bytes_atomic(path, sink.getvalue().to_pybytes())
