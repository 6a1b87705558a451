"""Fast paths that never fall back silently.

Some sources have two readers: a fast one written for the common layout (the OSI import's
columnar decoder, ROS 2's generated CDR deserialisers) and the library reader that takes
everything (betterosi, mcap-ros2-support). The fast one refuses only input it knows it does not
handle, by raising :class:`FastPathUnsupported` with the reason; anything else it raises — a bug
included — propagates, so that a defect shows as an error, not as a 2-4x slowdown. Which path
read a file is logged (logger ``aveas_format.converters``, level INFO: ``aveas-format convert
--verbose`` and ``validate --verbose`` print it)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")

log = logging.getLogger("aveas_format.converters")


class FastPathUnsupported(Exception):
    """A fast path does not take this input (``reason``: what it met); the other path reads it."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def read_by(what: str, fast: tuple[str, Callable[[], T]], other: tuple[str, Callable[[], T]]) -> T:
    """``fast``'s result, or ``other``'s where the fast path raises :class:`FastPathUnsupported`
    (every other exception propagates); ``what`` (e.g. the file) and the path that read it are
    logged, with the fast path's reason where it refused."""
    name, fn = fast
    try:
        out = fn()
    except FastPathUnsupported as e:
        log.info("%s: read by %s (%s does not take it: %s)", what, other[0], name, e.reason)
        return other[1]()
    log.info("%s: read by %s", what, name)
    return out
