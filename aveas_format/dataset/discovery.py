"""Which recordings a dataset spec names, and how a task reaches each one.

A spec is a recording, a directory (searched recursively for ``NAME.aveas/`` directories holding a
``recording.json`` and for ``NAME.aveas.zip`` files), a glob, a URL, or a list of those. URLs go
through :func:`pyarrow.fs.FileSystem.from_uri`: ``file://`` is read in place, any other scheme
pyarrow supports (``s3://``, ``gs://``, ``hdfs://``) is listed there and each recording is copied to
a temporary local directory inside the task that processes it (:func:`local_copy`; the reader
needs local files, see docs/datasets.md).
"""

from __future__ import annotations

import contextlib
import glob
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import Any

from aveas_format.errors import AveasError
from aveas_format.parallel import TaskResult, run_tasks

_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_GLOB = re.compile(r"[*?\[]")
_FILE = "file://"


def is_url(ref: str) -> bool:
    """Whether a recording reference is a URL (``scheme://...``, ``file://`` included)."""
    return bool(_URL.match(ref))


def file_path(ref: str) -> str:
    """The local path of a ``file://`` URL; any other reference unchanged."""
    return ref[len(_FILE):] if ref.startswith(_FILE) else ref


def is_recording(path: str | Path) -> bool:
    """A recording: a directory holding ``recording.json``, or a ``.zip`` file (``NAME.aveas.zip``)."""
    p = Path(path)
    if p.is_dir():
        return (p / "recording.json").is_file()
    return p.is_file() and p.name.lower().endswith(".zip")


def is_dataset_spec(specs: Iterable[str | Path]) -> bool:
    """Whether CLI arguments name a dataset (several recordings) rather than one recording: more
    than one argument, a glob, a URL, or a directory that is not itself a recording but holds some."""
    specs = [str(s) for s in specs]
    if len(specs) != 1:
        return len(specs) > 1
    s = specs[0]
    if is_url(s) or (_GLOB.search(s) and not Path(s).exists()):
        return True
    p = Path(s)
    if not p.is_dir() or is_recording(p) or p.name.endswith(".aveas"):
        return False
    return bool(_find_local(p))


def _find_local(root: Path) -> list[str]:
    """Recordings under a local directory (not descending into a recording)."""
    found: list[str] = []
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if "recording.json" in filenames and d != root:
            found.append(str(d))
            dirnames[:] = []
            continue
        dirnames[:] = sorted(n for n in dirnames if not n.startswith("."))
        for f in sorted(filenames):
            if f.lower().endswith(".aveas.zip"):
                found.append(str(d / f))
    if (root / "recording.json").is_file():
        return [str(root)]
    return sorted(found)


def _find_remote(url: str) -> list[str]:
    import pyarrow.fs as pafs

    try:
        fs, base = _filesystem_from_uri(url)
    except (_pa_errors() + (ValueError, OSError)) as e:
        raise AveasError(f"{url}: cannot open this URL with pyarrow.fs: {e}") from None
    base = base.rstrip("/") or "/"
    top, sep, query = url.partition("?")  # keep options such as ?region=... on every URL
    top = top.rstrip("/")

    def uri(p: str) -> str:
        """The URL of a path below ``base``: ``url`` + the relative part (works for every scheme,
        whether or not the filesystem path holds the bucket or host)."""
        rel = p[len(base):].strip("/") if p.startswith(base) else ""
        return (f"{top}/{rel}" if rel else top) + sep + query

    info = fs.get_file_info(base)
    if info.type == pafs.FileType.NotFound:
        raise AveasError(f"{url}: not found")
    if info.type == pafs.FileType.File:
        return [uri(base)]
    if fs.get_file_info(base + "/recording.json").type == pafs.FileType.File:
        return [uri(base)]
    out: set[str] = set()
    for fi in fs.get_file_info(pafs.FileSelector(base, recursive=True)):
        if fi.type != pafs.FileType.File:
            continue
        if fi.base_name == "recording.json":
            parent = fi.path.rsplit("/", 1)[0]
            if ".aveas.zip" not in parent:
                out.add(parent)
        elif fi.base_name.lower().endswith(".aveas.zip"):
            out.add(fi.path)
    # drop recordings nested inside other recordings
    keep = sorted(p for p in out if not any(p != q and p.startswith(q + "/") for q in out))
    return [uri(p) for p in keep]


def _filesystem_from_uri(uri: str) -> tuple[Any, str]:
    """(pyarrow filesystem, path in it) of a URL (one place, for tests to replace)."""
    import pyarrow.fs as pafs

    return pafs.FileSystem.from_uri(uri)


def _pa_errors() -> tuple[type[BaseException], ...]:
    import pyarrow as pa

    return (pa.ArrowException,)


def discover(*specs: str | Path | Iterable[str | Path]) -> list[str]:
    """Every recording a dataset spec names, sorted and without duplicates.

    Each spec is a recording, a directory (searched recursively), a glob (``archive/**/*.aveas``,
    ``**`` recursive), a URL (``file:///data/archive``, ``s3://bucket/archive``), or a list of those.
    Raises :class:`AveasError` for a directory, glob or URL that holds no recording; a path that
    does not exist is kept (its task fails with "no such recording", the others still run).
    """
    flat: list[str] = []
    for s in specs:
        if isinstance(s, (str, Path)):
            flat.append(str(s))
        else:
            flat.extend(str(x) for x in s)
    out: list[str] = []
    for s in flat:
        if s.startswith(_FILE):
            found = [file_path(r) for r in _find_remote(s)]
        elif is_url(s):
            found = _find_remote(s)
        elif Path(s).exists():
            found = [s] if is_recording(s) else (_find_local(Path(s)) if Path(s).is_dir() else [s])
        elif _GLOB.search(s):
            found = []
            for m in sorted(glob.glob(s, recursive=True)):
                found.extend([m] if is_recording(m) else _find_local(Path(m)) if Path(m).is_dir()
                             else [])
        else:
            found = [s]  # a missing recording: its task reports "no such recording"
        if not found:
            raise AveasError(f"{s}: no recordings found (NAME.aveas/ with recording.json, or "
                             "NAME.aveas.zip)")
        out.extend(found)
    seen: set[str] = set()
    uniq = []
    for p in out:
        key = p if is_url(p) else os.path.normpath(os.path.abspath(p))
        if key not in seen:
            seen.add(key)
            uniq.append(p)
    return uniq


@contextlib.contextmanager
def local_copy(ref: str) -> Iterator[str]:
    """A local path for a recording reference: the path itself, or a temporary copy of a remote one."""
    if not is_url(ref) or ref.startswith(_FILE):
        yield file_path(ref)
        return
    import pyarrow.fs as pafs

    fs, path = _filesystem_from_uri(ref)
    tmp = tempfile.mkdtemp(prefix="aveas-remote-")
    try:
        name = path.rstrip("/").rsplit("/", 1)[-1]
        target = os.path.join(tmp, name)
        if fs.get_file_info(path).type == pafs.FileType.File:
            pafs.copy_files(path, target, source_filesystem=fs,
                            destination_filesystem=pafs.LocalFileSystem())
        else:
            os.makedirs(target)
            pafs.copy_files(path, target, source_filesystem=fs,
                            destination_filesystem=pafs.LocalFileSystem())
        yield target
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def map_recordings(fn: Callable[[str], Any], paths: Iterable[str], *, workers: int | None = 1,
                   scheduler: str | None = None, progress: bool = False,
                   description: str = "recordings") -> Iterator[TaskResult]:
    """``fn(path)`` for every recording through :func:`~aveas_format.parallel.run_tasks`
    (``fn`` must be a module-level function or a :func:`functools.partial` of one)."""
    return run_tasks(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                     progress=progress, description=description)
