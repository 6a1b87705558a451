"""Byte access to the files of a recording, in directory form or single-file ZIP form.

Both forms give zero-copy, memory-mapped :class:`pyarrow.Buffer` views of each member, so a partial
read touches only the pages it needs. ZIP members are stored uncompressed (FORMAT.md 1), so a
member's bytes are a slice of the archive; a compressed member (written by another tool) is
decompressed into memory instead.
"""

from __future__ import annotations

import hashlib
import struct
import zipfile
from zlib import error as zlib_error
from pathlib import Path

import pyarrow as pa

from aveas_format.errors import RecordingIOError
from aveas_format.safeio import check_zip_member

_LOCAL_HEADER = struct.Struct("<IHHHHHIIIHH")  # 30 bytes, signature 0x04034b50


def sha256_of(buf: pa.Buffer | bytes | memoryview) -> str:
    return hashlib.sha256(memoryview(buf)).hexdigest()


def _not_a_zip(path: Path) -> str:
    """Why a file that :func:`zipfile.is_zipfile` does not take is not a recording: a ZIP archive
    cut short (it starts with a ZIP signature but has no central directory), an empty or foreign
    file named ``.zip``, or neither."""
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        return f"cannot read: {e.strerror or e}"
    if head in (b"PK\x03\x04", b"PK\x05\x06", b"PK\x07\x08"):
        return ("truncated or corrupt ZIP archive: no end-of-central-directory record (was the "
                "download or copy cut short?)")
    if path.name.lower().endswith(".zip"):
        return ("truncated or corrupt ZIP archive: the file is empty" if not head else
                "not a recording: named .zip but not a ZIP archive (no ZIP signature)")
    return "not a recording: neither a directory nor a ZIP archive"


class Container:
    """The files of one recording: ``NAME.aveas/`` or ``NAME.aveas.zip``."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise RecordingIOError("no such recording (neither a directory nor a .zip file)",
                                   path=self.path)
        self._zip: zipfile.ZipFile | None = None
        self._map: pa.Buffer | None = None
        self._prefix = ""
        if self.path.is_dir():
            self.form = "directory"
        elif zipfile.is_zipfile(self.path):
            self.form = "zip"
            try:
                self._zip = zipfile.ZipFile(self.path)
            except (zipfile.BadZipFile, OSError) as e:
                raise RecordingIOError(f"corrupt ZIP archive: {e}", path=self.path) from None
            for info in self._zip.infolist():
                check_zip_member(info, self.path)
            names = self._zip.namelist()
            # tolerate archives made with the directory itself as top-level entry
            if "recording.json" not in names:
                tops = {n.split("/", 1)[0] + "/" for n in names if n.endswith("recording.json")
                        and n.count("/") == 1}
                if len(tops) == 1:
                    self._prefix = tops.pop()
        else:
            raise RecordingIOError(_not_a_zip(self.path), path=self.path)

    # -- listing -----------------------------------------------------------------------------
    def names(self) -> list[str]:
        """Relative paths of all member files (POSIX separators)."""
        if self._zip is not None:
            p = self._prefix
            return sorted(n[len(p):] for n in self._zip.namelist()
                          if n.startswith(p) and not n.endswith("/"))
        return sorted(q.relative_to(self.path).as_posix() for q in self.path.rglob("*") if q.is_file())

    def exists(self, name: str) -> bool:
        if self._zip is not None:
            try:
                self._zip.getinfo(self._prefix + name)
                return True
            except KeyError:
                return False
        return (self.path / name).is_file()

    def location(self, name: str) -> str:
        """How to name a member in messages: ``rec.aveas/states.parquet`` or ``rec.zip!states.parquet``."""
        return f"{self.path}!{name}" if self._zip is not None else str(self.path / name)

    # -- reading -----------------------------------------------------------------------------
    def buffer(self, name: str) -> pa.Buffer:
        """A (memory-mapped where possible) buffer of one member's bytes."""
        if not self.exists(name):
            raise RecordingIOError("file missing from the recording", path=self.location(name))
        try:
            if self._zip is None:
                path = self.path / name
                if path.stat().st_size == 0:
                    return pa.py_buffer(b"")
                with pa.memory_map(str(path), "r") as mm:
                    return mm.read_buffer()
            return self._zip_member(name)
        except OSError as e:
            raise RecordingIOError(f"cannot read: {e}", path=self.location(name)) from None

    def _zip_member(self, name: str) -> pa.Buffer:
        assert self._zip is not None
        info = self._zip.getinfo(self._prefix + name)
        if info.flag_bits & 0x1:
            raise RecordingIOError("encrypted ZIP member; refused", path=self.location(name))
        if info.compress_type != zipfile.ZIP_STORED:
            try:
                return pa.py_buffer(self._zip.read(info))
            except (zipfile.BadZipFile, EOFError, NotImplementedError, zlib_error) as e:
                raise RecordingIOError(f"corrupt ZIP member: {e}", path=self.location(name)) from None
        if self._map is None:
            with pa.memory_map(str(self.path), "r") as mm:
                self._map = mm.read_buffer()
        header = self._map.slice(info.header_offset, _LOCAL_HEADER.size).to_pybytes()
        fields = _LOCAL_HEADER.unpack(header)
        if fields[0] != 0x04034B50:
            raise RecordingIOError("corrupt ZIP archive (bad local header)", path=self.location(name))
        start = info.header_offset + _LOCAL_HEADER.size + fields[9] + fields[10]
        if start + info.file_size > self._map.size:
            raise RecordingIOError("ZIP member is truncated", path=self.location(name))
        return self._map.slice(start, info.file_size)

    def read_bytes(self, name: str) -> bytes:
        return self.buffer(name).to_pybytes()

    def input_file(self, name: str) -> pa.NativeFile:
        """A random-access file of one member for reading part of it (Parquet row groups): a plain
        file for a directory (read with ``pread``, so only what is read is held in memory), a
        reader over the member's bytes in a ZIP."""
        if self._zip is None:
            if not self.exists(name):
                raise RecordingIOError("file missing from the recording", path=self.location(name))
            try:
                return pa.OSFile(str(self.path / name), "rb")
            except OSError as e:
                raise RecordingIOError(f"cannot read: {e}", path=self.location(name)) from None
        return pa.BufferReader(self.buffer(name))

    def sha256(self, name: str, chunk: int = 1 << 20) -> str:
        """SHA-256 of one member, hashed in chunks (a directory's file is never held whole)."""
        if self._zip is not None:
            return sha256_of(self.buffer(name))
        h = hashlib.sha256()
        try:
            with open(self.path / name, "rb") as f:
                while block := f.read(chunk):
                    h.update(block)
        except OSError as e:
            raise RecordingIOError(f"cannot read: {e}", path=self.location(name)) from None
        return h.hexdigest()

    def close(self) -> None:
        if self._zip is not None:
            self._zip.close()
        self._map = None

    def __enter__(self) -> Container:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
