"""The compiled assembler of the export's rows (numba, the ``jit`` extra): the text of each state's
object put together from spans of one buffer, no Python object per value.

:class:`~.encode._Layout` formats every number of a chunk with one ``orjson`` call per kind and
gathers the constants, the formatted numbers and the other fragments in one byte buffer ``g``;
each row then is a *program* (the ops of its group of rows with the same items present): an op
``k >= 0`` is the row's value ``k`` (``g[start[i, k]:end[i, k]]``), an op ``< 0`` the constant
``-op - 1`` (``g[cstart[c]:cend[c]]``). :func:`assemble` copies them into one output buffer
(the export's whole chunk: the frames' heads and ends are fragments of the rows). The Python path
of the same layout (one ``template % values`` per row) writes the same bytes; the tests compare
the two. :func:`number_spans` finds the formatted numbers' spans in orjson's text.

Imported only where numba is installed (:func:`aveas_format.numeric.kernel_backend` decides); the
first call in an environment compiles it (~2 s) and caches the machine code next to this module.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True, nogil=True)
def assemble(g, cstart, cend, prog, prog_off, group, start, end):  # pragma: no cover - compiled
    """The rows' bytes one after the other in one buffer: row ``i`` runs its group's program
    ``prog[prog_off[group[i]]:prog_off[group[i] + 1]]`` (see the module)."""
    m = len(group)
    n = 0
    for i in range(m):
        gi = group[i]
        for p in range(prog_off[gi], prog_off[gi + 1]):
            op = prog[p]
            if op < 0:
                n += cend[-op - 1] - cstart[-op - 1]
            else:
                n += end[i, op] - start[i, op]
    out = np.empty(n, np.uint8)
    # (unsigned indices: numba checks signed ones for a negative value, which keeps the copy
    # from being compiled into wide moves: 5x slower on the short pieces here)
    o = numba.uint64(0)
    for i in range(m):
        gi = group[i]
        for p in range(prog_off[gi], prog_off[gi + 1]):
            op = prog[p]
            if op < 0:
                a, b = numba.uint64(cstart[-op - 1]), numba.uint64(cend[-op - 1])
            else:
                a, b = numba.uint64(start[i, op]), numba.uint64(end[i, op])
            while a < b:
                out[o] = g[a]
                o += numba.uint64(1)
                a += numba.uint64(1)
    return out


@numba.njit(cache=True, nogil=True)
def number_spans(b, at, widths, cols, start, end):  # pragma: no cover - compiled
    """Where the numbers of one JSON array ``b`` (``[n,n,...]``, as orjson writes a flat numpy
    array: no spaces, no nested arrays) start and end, offset by ``at``: the values one after
    the other, value ``v`` ``widths[v]`` numbers in each of the ``start.shape[0]`` rows (a
    vector's components), its spans (from its row's first number to the end of its last: the
    commas between them included) into column ``cols[v]`` of ``start``/``end``."""
    m = start.shape[0]
    q = numba.uint64(1)  # (after "[")
    base = numba.uint64(at)  # (unsigned + unsigned: an int64 with a uint64 would be a float64)
    comma, close = numba.uint8(44), numba.uint8(93)
    for v in range(len(widths)):
        c = cols[v]
        for i in range(m):
            start[i, c] = base + q
            for k in range(widths[v]):
                if k:
                    q += numba.uint64(1)  # (the comma between two components)
                while b[q] != comma and b[q] != close:
                    q += numba.uint64(1)
            end[i, c] = base + q
            q += numba.uint64(1)  # (the comma after the span, or the closing bracket)


#: the argument types of :func:`assemble` as the export passes them (one compile)
_EXAMPLE = (np.frombuffer(b"[1]", np.uint8), np.zeros(1, np.int64), np.ones(1, np.int64),
            np.array([-1, 0], np.int64), np.array([0, 2], np.int64), np.zeros(1, np.int64),
            np.ones((1, 1), np.int64), np.full((1, 1), 2, np.int64))


_WARM = False


def warm() -> None:
    """Compile :func:`assemble`, or load it from numba's cache, once per process (before the
    export forks its encoders: they inherit it)."""
    global _WARM
    if not _WARM:
        assert bytes(assemble(*_EXAMPLE)) == b"[1"
        start, end = np.zeros((1, 2), np.int64), np.zeros((1, 2), np.int64)
        number_spans(np.frombuffer(b"[1,-2.5,null]", np.uint8), 0, np.array([1, 2], np.int64),
                     np.array([1, 0], np.int64), start, end)
        assert start.tolist() == [[3, 1]] and end.tolist() == [[12, 2]]
        _WARM = True
