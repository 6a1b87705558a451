"""A compiled reader of a block of OpenLABEL frames in the AVEAS profile's layout (numba, the ``jit``
extra): one pass over the bytes, a validating recursive-descent parser that knows the box layout
and writes what the import reads as flat arrays, no Python object per value.

:func:`parse_block` walks ``{"key":{frame},...}``: each frame's members (``objects`` read box by
box, every other member skipped with its syntax checked: the caller parses the frames' skeleton
with orjson), each box ``{"object_data":{"cuboid":[...],"boolean":[...],"num":[...],"text":[...],
"vec":[...]}}`` strictly. It gives back

- per box its byte span and where its cuboid's 9 numbers start;
- per attribute item its box, kind (:data:`KINDS`' order), name and value (a number, a string,
  a boolean, or a run of numbers for ``vec``);
- per member of the cuboid's ``aveas_format`` extension item its box, key and scalar value;
- the numbers as their JSON text, packed (the caller converts them in one Arrow cast: correctly
  rounded, as a JSON parser reads them), the texts packed the same way, each distinct name once.

A key of the layout is read by comparing its bytes with the word expected, an item's name with the
name expected (the one after the item before in the table of names: the items come in the same
order box after box) — a string ends at its first quote, so the bytes and a quote after them are
that string; where they differ, the long way (scanned, escapes checked, the name looked up). At
2M states: 19.2 -> 15.7 ms per 8 MiB block.

**Boxes read by template.** The boxes of a block come in a handful of shapes (the same attributes
and extension members in the same order; only the values differ), so once the parser has read a
box of a shape, the next box of that shape is the same literal bytes with other values in the same
places. :func:`build` cuts a box the parser has read into its literal bytes and its value slots —
each number (an int or a float, as its text says) and each string the parser stored (a ``text``
item's value, an extension member's string; keys and item names are literal) — and keeps the rows
the parser wrote for it with their values relative to the box's first number and string.
:func:`match` reads a box by a template: every literal byte compared, every number read by the
strict grammar and of the template's int/float kind, every string without escapes or control
characters (which the parser refuses in a box too); the rows are the template's with this box's
values. So a box that matches reads exactly as the parser would read it (tests: the same arrays
with ``by_template=False``); one that does not (another shape, a ``true`` where the template has
``false``, a broken value) is read by the parser and becomes a template, replacing the least
recently matched of :data:`TEMPLATES`. The names' codes of a template stay valid in its block
(the table only grows). At 2M states an 8 MiB block's ~7,100 boxes come in ~8 shapes, consecutive
boxes differ in ~70 % of cases, 8 of them are parsed and the rest matched (1.5 tries per box, the
templates tried last matched first): the block 81-89 -> 59-66 ms here (the parser's numbers, too,
recorded as spans and their texts gathered once at the end of the block instead of copied one by
one).

Anything outside the profile's layout — a member the layout does not have, a repeated member, a
``null``, a string with an escape in a box, a rotated or second cuboid, a value of another type —
and any syntax error stops it with status 1: the caller falls back to the Arrow or the generic
path, which reads the block or names the error. Imported only where numba is installed
(:func:`aveas_format.numeric.kernel_backend` decides); the first call in an environment compiles
it (~30 s on the seventh session's VM before the templates; on the slow VM of 2026-12 103-110 s
with them against 68 s without: the helpers are inlined into one large function, which runs
~1.5x faster than calls to them would) and caches the machine code next to this module. All of
the reader is in this one file, longer than the house's ~800 lines for that reason: numba's cache
is invalidated by a change to the file that defines a compiled function, not by one to the
functions it inlines from other files (a helper in a module of its own, edited, would leave the
parser's cached code stale).
"""

from __future__ import annotations

import numba
import numpy as np
_jit = numba.njit(cache=True, nogil=True, inline="always")
_jit_call = numba.njit(cache=True, nogil=True)
_jit_loop = numba.njit(cache=True, nogil=True)

#: the item kinds: the order of :data:`.fastblock.KINDS`, then the cuboid
K_BOOLEAN, K_NUM, K_TEXT, K_VEC, K_CUBOID = 0, 1, 2, 3, 4
#: extension values: a number with a fraction or an exponent (a float to a JSON parser), true,
#: false, a string, a number without (an int)
E_FLOAT, E_TRUE, E_FALSE, E_STR, E_INT = 0, 1, 2, 3, 4
#: the deepest nesting a skipped value may have here (deeper: the generic path, which knows the limit)
_MAX_SKIP_DEPTH = 64


def _word(s: bytes) -> np.ndarray:
    return np.frombuffer(s, np.uint8).copy()


_OBJECTS = _word(b"objects")
_OBJECT_DATA = _word(b"object_data")
_NAME = _word(b"name")
_VAL = _word(b"val")
_EXT = _word(b"aveas_format")
_BOUNDING_BOX = _word(b"bounding_box")
_KIND_BOOLEAN = _word(b"boolean")
_KIND_NUM = _word(b"num")
_KIND_TEXT = _word(b"text")
_KIND_VEC = _word(b"vec")
_KIND_CUBOID = _word(b"cuboid")
_TRUE = _word(b"true")
_FALSE = _word(b"false")
_NULL = _word(b"null")


@_jit
def _ws(b, i):
    if b[i] > 32:
        return i
    while b[i] == 32 or b[i] == 10 or b[i] == 13 or b[i] == 9:
        i += 1
    return i


@_jit
def _eq(b, s, e, w):
    """Whether ``b[s:e]`` is the word ``w``."""
    if e - s != w.size:
        return False
    for k in range(w.size):
        if b[s + k] != w[k]:
            return False
    return True


@_jit
def _key(b, i, w):
    """Past the string at ``i`` (``b[i]`` a quote) where it is the plain word ``w``, else -1
    (the caller reads it the long way then)."""
    m = w.size
    if i + m + 1 >= b.size or b[i + m + 1] != 34:
        return -1
    for k in range(m):
        if b[i + 1 + k] != w[k]:
            return -1
    return i + m + 2


@_jit
def _known(b, i, tbuf, toff, c, nt):
    """Past the string at ``i`` where it is the name ``c`` of the table, else -1."""
    if c < 0 or c >= nt:
        return -1
    o = toff[c]
    m = toff[c + 1] - o
    if i + m + 1 >= b.size or b[i + m + 1] != 34:
        return -1
    for k in range(m):
        if b[i + 1 + k] != tbuf[o + k]:
            return -1
    return i + m + 2


@_jit
def _hex(c):
    return (48 <= c <= 57) or (65 <= c <= 70) or (97 <= c <= 102)


@_jit_call
def _string(b, i, n):
    """``b[i]`` is a quote: ``(index past the closing quote or -1 where broken, has an escape)``;
    escapes checked as JSON defines them, control characters refused."""
    i += 1
    esc = False
    while i < n:
        c = b[i]
        if c > 92 or (c > 34 and c < 92):
            i += 1
            continue
        if c == 34:
            return i + 1, esc
        if c == 92:
            esc = True
            d = b[i + 1]
            if d == 117:
                if not (_hex(b[i + 2]) and _hex(b[i + 3]) and _hex(b[i + 4]) and _hex(b[i + 5])):
                    return -1, esc
                i += 6
                continue
            if not (d == 34 or d == 92 or d == 47 or d == 98 or d == 102 or d == 110 or d == 114 or d == 116):
                return -1, esc
            i += 2
            continue
        if c < 32:
            return -1, esc
        i += 1
    return -1, esc


@_jit
def _number_kind(b, i):
    """``(end, has a fraction or an exponent)`` of the JSON number at ``i``; end -1 where there is
    none (the strict grammar)."""
    j = i
    fl = False
    if b[j] == 45:
        j += 1
    if b[j] == 48:
        j += 1
    elif 49 <= b[j] <= 57:
        while 48 <= b[j] <= 57:
            j += 1
    else:
        return -1, fl
    if b[j] == 46:
        fl = True
        j += 1
        k = j
        while 48 <= b[j] <= 57:
            j += 1
        if j == k:
            return -1, fl
    if b[j] == 101 or b[j] == 69:
        fl = True
        j += 1
        if b[j] == 43 or b[j] == 45:
            j += 1
        k = j
        while 48 <= b[j] <= 57:
            j += 1
        if j == k:
            return -1, fl
    return j, fl


@_jit
def _number(b, i):
    """The end of the JSON number at ``i``, -1 where there is none (the strict grammar)."""
    return _number_kind(b, i)[0]


@_jit
def _literal(b, i, w):
    """The end of the literal ``w`` at ``i``, -1 where it is not there."""
    for k in range(w.size):
        if b[i + k] != w[k]:
            return -1
    return i + w.size



@_jit_call
def _grow(a, need):
    """``a`` with room for ``need`` rows (doubled, the rows kept)."""
    if need <= a.shape[0]:
        return a
    size = max(need, 2 * a.shape[0])
    out = np.empty((size,) + a.shape[1:], a.dtype)
    out[:a.shape[0]] = a
    return out


@_jit
def _put(b, s, e, data, offs, k):
    """``b[s:e]`` as the ``k``-th packed text of ``(data, offs)`` (offs[0] == 0)."""
    if k + 2 > offs.size:
        offs = _grow(offs, k + 2)
    start = offs[k]
    end = start + e - s
    if end > data.size:
        data = _grow(data, end)
    data[start:end] = b[s:e]
    offs[k + 1] = end
    return data, offs


@_jit
def _intern(b, s, e, tbuf, toff, nt, hint):
    """The code of the name ``b[s:e]`` in the table ``(tbuf, toff)`` of ``nt`` names (``hint``
    tried first: the items of a box come in the same order box after box); a new name is added.
    Returns ``(code, tbuf, toff, nt)``."""
    size = e - s
    for k in range(-1, nt):
        c = hint if k < 0 else k
        if c < 0 or c >= nt or toff[c + 1] - toff[c] != size:
            continue
        o = toff[c]
        same = True
        for j in range(size):
            if tbuf[o + j] != b[s + j]:
                same = False
                break
        if same:
            return c, tbuf, toff, nt
    tbuf, toff = _put(b, s, e, tbuf, toff, nt)
    return nt, tbuf, toff, nt + 1


@_jit
def _span(s, e, spans, k):
    """``b[s:e]`` as the ``k``-th span of ``spans`` (rows ``[start, end]``; grown where needed):
    the numbers' texts are gathered into one packed text at the end of a block
    (:func:`_gather`), not copied one by one while parsing (~1.4-2 us less per box)."""
    if k >= spans.shape[0]:
        spans = _grow(spans, k + 1)
    spans[k, 0] = s
    spans[k, 1] = e
    return spans


@_jit_call
def _gather(b, spans, k, data, offs):
    """The first ``k`` spans of ``b`` as packed text ``(data, offs)`` (grown where needed)."""
    size = 0
    for r in range(k):
        size += spans[r, 1] - spans[r, 0]
    data = _grow(data, size)
    offs = _grow(offs, k + 1)
    o = 0
    offs[0] = 0
    for r in range(k):
        s = spans[r, 0]
        for j in range(spans[r, 1] - s):
            data[o + j] = b[s + j]
        o += spans[r, 1] - s
        offs[r + 1] = o
    return data, offs



@_jit
def _colon(b, i):
    """Past the ``:`` after a key (at ``i``, whitespace around it skipped), -1 where there is none."""
    i = _ws(b, i)
    return _ws(b, i + 1) if b[i] == 58 else -1


@_jit
def _next(b, i, close):
    """After a member or an element at ``i``: ``(past a comma, 1)``, ``(past the closing bracket
    ``close``, 0)`` or ``(i, -1)`` where neither follows."""
    i = _ws(b, i)
    if b[i] == 44:
        return _ws(b, i + 1), 1
    if b[i] == close:
        return i + 1, 0
    return i, -1


# ------------------------------------------------------------------------------------------------
# boxes read by template (the module's docstring)

#: templates kept per block
TEMPLATES = 8
#: a template's limits: literal bytes, value slots, item rows, extension rows (a larger box: no
#: template, the parser reads it)
MAX_LITERAL, MAX_SLOTS, MAX_ITEMS, MAX_EXT = 4096, 512, 128, 64
#: a slot's kind
S_INT, S_FLOAT, S_STR = 0, 1, 2
#: meta columns: slots, items, ext rows, numbers, strings, cuboid's first number (relative), the
#: names' hint after the box (the literal's length: the end of the last segment)
M_SLOTS, M_ITEMS, M_EXT, M_NUMS, M_STRS, M_CUB, M_HINT = range(7)


@_jit_call
def templates():
    """Empty template storage for one block: ``(lit, seg, kind, items, ext, meta, order, common,
    at)``: ``order`` lists the templates in use, last matched first (-1: free); ``common[t, u]``
    how many slots templates t and u begin with alike (literal bytes and kinds); ``at`` the box's
    position at each slot's literal as the last try met it."""
    t = TEMPLATES
    return (np.empty((t, MAX_LITERAL), np.uint8), np.empty((t, MAX_SLOTS + 1), np.int64),
            np.empty((t, MAX_SLOTS), np.int8), np.empty((t, MAX_ITEMS, 5), np.int64),
            np.empty((t, MAX_EXT, 4), np.int64), np.zeros((t, 7), np.int64), np.full(t, -1, np.int64),
            np.zeros((t, t), np.int64), np.zeros(MAX_SLOTS + 1, np.int64))


@_jit_call
def build(b, s, e, nums0, nums1, nspan, strs0, strs1, sspan, items, i0, i1, ext, e0, e1, cub_first, hint,
          lit, seg, kind, titems, text, meta, order, common):
    """Make the box ``b[s:e]`` that the parser has read (its numbers ``nums0:nums1`` at the spans
    ``nspan``, strings ``strs0:strs1`` at ``sspan``, item rows ``i0:i1``, extension rows ``e0:e1``)
    the most recent template (replacing the least recently matched). Returns False where it cannot
    be one: larger than the limits, or its value slots are not exactly the values the parser
    stored (a member it skips; a value it stores that the cut takes for literal)."""
    if i1 - i0 > MAX_ITEMS or e1 - e0 > MAX_EXT:
        return False
    t = order.size - 1
    slot = order[t]
    order[t] = -1  # (out of use while it is rewritten: a box it cannot take leaves it free)
    if slot < 0:  # a free one
        used = np.zeros(order.size, np.bool_)
        for k in range(order.size):
            if order[k] >= 0:
                used[order[k]] = True
        for k in range(order.size):
            if not used[k]:
                slot = k
                break
    lt, sg, kd = lit[slot], seg[slot], kind[slot]
    n_lit = 0
    n_slot = 0
    n_num = 0
    n_str = 0
    after_name = False  # (the value after a "name" key: the item's name, literal)
    i = s
    while i < e:
        c = b[i]
        if c == 34:
            j, esc = _string(b, i, e)
            if j < 0 or esc:
                return False
            k = j
            while b[k] == 32 or b[k] == 10 or b[k] == 13 or b[k] == 9:
                k += 1
            is_key = b[k] == 58
            if is_key or after_name:
                if n_lit + j - i > MAX_LITERAL:
                    return False
                lt[n_lit:n_lit + j - i] = b[i:j]
                n_lit += j - i
                after_name = is_key and j - i == 6 and b[i + 1] == 110 and b[i + 2] == 97 \
                    and b[i + 3] == 109 and b[i + 4] == 101
            else:
                if n_slot == MAX_SLOTS or n_str == strs1 - strs0 or sspan[strs0 + n_str, 0] != i:
                    return False
                sg[n_slot] = n_lit
                kd[n_slot] = S_STR
                n_slot += 1
                n_str += 1
            i = j
        elif c == 45 or (48 <= c <= 57):
            j, fl = _number_kind(b, i)
            if j < 0 or n_slot == MAX_SLOTS or n_num == nums1 - nums0 or nspan[nums0 + n_num, 0] != i:
                return False
            sg[n_slot] = n_lit
            kd[n_slot] = S_FLOAT if fl else S_INT
            n_slot += 1
            n_num += 1
            after_name = False
            i = j
        else:
            if n_lit == MAX_LITERAL:
                return False
            lt[n_lit] = c
            n_lit += 1
            i += 1
    if n_num != nums1 - nums0 or n_str != strs1 - strs0:
        return False
    sg[n_slot] = n_lit
    ti, te = titems[slot], text[slot]
    for r in range(i1 - i0):
        for c in range(5):
            ti[r, c] = items[i0 + r, c]
        k = items[i0 + r, 1]
        if k == K_NUM or k == K_VEC:
            ti[r, 3] -= nums0
        elif k == K_TEXT:
            ti[r, 3] -= strs0
    for r in range(e1 - e0):
        for c in range(4):
            te[r, c] = ext[e0 + r, c]
        k = ext[e0 + r, 2]
        if k == E_FLOAT or k == E_INT:
            te[r, 3] -= nums0
        elif k == E_STR:
            te[r, 3] -= strs0
    m = meta[slot]
    m[M_SLOTS], m[M_ITEMS], m[M_EXT] = n_slot, i1 - i0, e1 - e0
    m[M_NUMS], m[M_STRS], m[M_CUB], m[M_HINT] = n_num, n_str, cub_first - nums0, hint
    for u in order:  # (the slots it begins with alike with each other template)
        if u < 0 or u == slot:
            continue
        c = 0
        pu = ps = 0
        while c < min(n_slot, meta[u, M_SLOTS]) and kind[u, c] == kd[c] and seg[u, c] - pu == sg[c] - ps:
            same = True
            for k in range(sg[c] - ps):
                if lit[u, pu + k] != lt[ps + k]:
                    same = False
                    break
            if not same:
                break
            pu, ps = seg[u, c], sg[c]
            c += 1
        common[slot, u] = common[u, slot] = c
    for k in range(order.size - 1, 0, -1):  # (most recent first)
        order[k] = order[k - 1]
    order[0] = slot
    return True


@_jit
def match(b, i, c, n, slot, lit, seg, kind, meta, nspan, nn, sbuf, soff, ns, at):
    """Read the box at ``b[i]`` by template ``slot``: its numbers' spans into ``nspan`` from row
    ``nn`` on, its strings into ``(sbuf, soff)`` from ``ns`` on (room for the template's slots
    made by the caller), from slot ``c`` on: the slots before it as a try before met them (``at``:
    where each slot's literal began; this template begins with those slots alike). Returns ``(end
    of the box, ...)``, ``(-1, slot where it differs)`` where it does not match, ``(-2, ...)`` where
    ``sbuf`` has no room (nothing is counted: the caller grows it and tries again)."""
    lt, sg, kd, m = lit[slot], seg[slot], kind[slot], meta[slot]
    p = 0
    if c > 0:
        i = at[c]
        p = sg[c - 1]
        for j in range(c):
            if kd[j] == S_STR:
                ns += 1
            else:
                nn += 1
    for j in range(c, m[M_SLOTS] + 1):
        at[j] = i
        q = sg[j]
        if i + q - p >= n:
            return -1, j
        for k in range(q - p):
            if b[i + k] != lt[p + k]:
                return -1, j
        i += q - p
        p = q
        if j == m[M_SLOTS]:
            break
        if kd[j] == S_STR:
            if b[i] != 34:
                return -1, j
            e = i + 1
            while b[e] != 34:
                if b[e] == 92 or b[e] < 32:  # (an escape, a control character, the end: the parser)
                    return -1, j
                e += 1
            o = soff[ns]
            if o + e - i - 1 > sbuf.size:
                return -2, j
            for k in range(e - i - 1):  # (a loop: faster than a slice's copy for a few bytes)
                sbuf[o + k] = b[i + 1 + k]
            soff[ns + 1] = o + e - i - 1
            ns += 1
            i = e + 1
        else:
            e, fl = _number_kind(b, i)
            if e < 0 or fl != (kd[j] == S_FLOAT):
                return -1, j
            nspan[nn, 0] = i
            nspan[nn, 1] = e
            nn += 1
            i = e
    return i, 0


@_jit_call
def rows(slot, nb, nn, ns, titems, text, meta, items, ni, ext, ne):
    """The rows of a box read by template ``slot`` as box ``nb`` (its first number ``nn``, string
    ``ns``) into ``items`` from row ``ni`` and ``ext`` from ``ne`` (room made by the caller)."""
    m, ti, te = meta[slot], titems[slot], text[slot]
    for r in range(m[M_ITEMS]):
        k = ti[r, 1]
        items[ni + r, 0] = nb
        items[ni + r, 1] = k
        items[ni + r, 2] = ti[r, 2]
        items[ni + r, 3] = ti[r, 3] + (nn if k == K_NUM or k == K_VEC else ns if k == K_TEXT else 0)
        items[ni + r, 4] = ti[r, 4]
    for r in range(m[M_EXT]):
        k = te[r, 2]
        ext[ne + r, 0] = nb
        ext[ne + r, 1] = te[r, 1]
        ext[ne + r, 2] = k
        ext[ne + r, 3] = te[r, 3] + (nn if k == E_FLOAT or k == E_INT else ns if k == E_STR else 0)


# ------------------------------------------------------------------------------------------------
# blocks
#: boxes read by the parser, after one that cannot be a template, before the next is tried
NO_BUILD_AFTER_FAILURE = 64
#: templates made in a block before they are given up for its rest where fewer boxes matched one
#: than were made into one (boxes of many shapes: every box would be tried, parsed and cut)
GIVE_UP_AFTER_BUILDS = 4 * TEMPLATES


@_jit_loop
def _skip(b, i, n):
    """``(end, nesting)`` of the JSON value at ``i``, its syntax checked (end -1: broken or
    deeper than :data:`_MAX_SKIP_DEPTH`); ``nesting``: the containers' depth inside it."""
    stack = np.zeros(_MAX_SKIP_DEPTH, np.uint8)  # 1: an object, 2: an array
    d = 0
    deepest = 0
    while True:
        # a value at i
        c = b[i]
        if c == 123 or c == 91:
            if d == _MAX_SKIP_DEPTH:
                return -1, deepest
            stack[d] = 1 if c == 123 else 2
            d += 1
            deepest = max(deepest, d)
            i = _ws(b, i + 1)
            if (c == 123 and b[i] == 125) or (c == 91 and b[i] == 93):
                d -= 1
                i += 1
            elif c == 123:
                if b[i] != 34:
                    return -1, deepest
                i, _ = _string(b, i, n)
                if i < 0:
                    return -1, deepest
                i = _colon(b, i)
                if i < 0:
                    return -1, deepest
                continue
            else:
                continue
        elif c == 34:
            i, _ = _string(b, i, n)
        elif c == 116:
            i = _literal(b, i, _TRUE)
        elif c == 102:
            i = _literal(b, i, _FALSE)
        elif c == 110:
            i = _literal(b, i, _NULL)
        else:
            i = _number(b, i)
        if i < 0:
            return -1, deepest
        # after a value: a separator or the ends of containers
        while True:
            if d == 0:
                return i, deepest
            i = _ws(b, i)
            c = b[i]
            top = stack[d - 1]
            if c == 44:
                i = _ws(b, i + 1)
                if top == 1:
                    if b[i] != 34:
                        return -1, deepest
                    i, _ = _string(b, i, n)
                    if i < 0:
                        return -1, deepest
                    i = _colon(b, i)
                    if i < 0:
                        return -1, deepest
                break
            if (c == 125 and top == 1) or (c == 93 and top == 2):
                d -= 1
                i += 1
                continue
            return -1, deepest



def scratch(n: int) -> tuple:
    """Fresh arrays for :func:`parse_block` sized for a block of ``n`` bytes (a caller keeps the
    ones it returns for the next block: no fresh pages per block)."""
    return (np.empty((max(16, n // 2048), 3), np.int64), np.empty((max(16, n // 96), 5), np.int64),
            np.empty((max(16, n // 256), 4), np.int64), np.empty(max(64, n // 2), np.uint8),
            np.zeros(max(16, n // 20), np.int64), np.empty(max(64, n // 8), np.uint8),
            np.zeros(max(16, n // 40), np.int64), np.empty(1024, np.uint8), np.zeros(64, np.int64),
            np.empty((max(16, n // 20), 2), np.int64), np.empty((max(16, n // 256), 2), np.int64))



@_jit_loop
def parse_block(b, boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff, nspan, sspan, by_template=True):
    """Parse the block ``b`` (uint8, ``{...}`` followed by one NUL byte) into the arrays given
    (:func:`scratch`; grown where needed). Returns ``(status, deepest nesting (the block's own
    braces: 1), rows used of boxes, items, ext, numbers, texts, names, and the arrays)``: boxes
    ``[start, end, first cuboid number]``, items ``[box, kind, name, value, count]``, ext ``[box,
    key, kind, value]``, the numbers' text and offsets, the texts' text and offsets, the names'
    text and offsets (the names of the attributes and of the extension's members, each once;
    ``name`` and ``key`` are indices into them), the numbers' spans (their texts are gathered
    from them at the end) and the texts' (both scratch; a template is checked against them).
    Status 0: read, 1: not this layout or broken (nothing else is meaningful then). A box of a
    shape read before is read by template (the module's docstring; the same arrays with
    ``by_template=False``: every box by the parser)."""
    n = b.size - 1
    noff[0] = 0
    soff[0] = 0
    toff[0] = 0
    nb = ni = ne = nn = ns = nt = 0
    hint = -1
    deepest = 1
    fail = (1, 0, 0, 0, 0, 0, 0, 0, boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff, nspan, sspan)
    lit, seg, tkind, titems, text, meta, order, common, at = templates()
    no_build = 0
    use_templates = by_template
    built = matched = 0

    i = _ws(b, 0)
    if b[i] != 123:
        return fail
    i = _ws(b, i + 1)
    if b[i] == 125:
        i += 1
    else:
        while True:  # the frames: "key": {members}
            if b[i] != 34:
                return fail
            i, _ = _string(b, i, n)
            if i < 0:
                return fail
            i = _colon(b, i)
            if i < 0:
                return fail
            if b[i] != 123:
                return fail
            deepest = max(deepest, 2)
            i = _ws(b, i + 1)
            if b[i] == 125:
                i += 1
            else:
                while True:  # the frame's members
                    if b[i] != 34:
                        return fail
                    ks = i
                    i, esc = _string(b, i, n)
                    if i < 0:
                        return fail
                    is_objects = not esc and _eq(b, ks + 1, i - 1, _OBJECTS)
                    i = _colon(b, i)
                    if i < 0:
                        return fail
                    if not is_objects:
                        i, d = _skip(b, i, n)
                        if i < 0:
                            return fail
                        deepest = max(deepest, 2 + d)
                    else:
                        if b[i] != 123:
                            return fail
                        deepest = max(deepest, 3)
                        i = _ws(b, i + 1)
                        if b[i] == 125:
                            i += 1
                        else:
                            while True:  # the objects: "uid": {box}
                                if b[i] != 34:
                                    return fail
                                i, _ = _string(b, i, n)
                                if i < 0:
                                    return fail
                                i = _colon(b, i)
                                if i < 0:
                                    return fail
                                # ---- a box: {"object_data": {kind: [items], ...}}
                                if b[i] != 123:
                                    return fail
                                box_start = i
                                tend = -1
                                if nspan.shape[0] < nn + MAX_SLOTS + 1:
                                    nspan = _grow(nspan, nn + MAX_SLOTS + 1)
                                if soff.size < ns + MAX_SLOTS + 2:
                                    soff = _grow(soff, ns + MAX_SLOTS + 2)
                                last = -1  # (the template tried last, and the slot where it differed)
                                differs = 0
                                for tk in range(order.size if use_templates else 0):  # (templates, last matched first)
                                    tt = order[tk]
                                    if tt < 0:
                                        break
                                    c = 0 if last < 0 else min(common[last, tt], differs)
                                    tend, tdiff = match(b, i, c, n, tt, lit, seg, tkind, meta, nspan, nn, sbuf, soff,
                                                        ns, at)
                                    while tend == -2:
                                        sbuf = _grow(sbuf, 2 * sbuf.size)
                                        tend, tdiff = match(b, i, c, n, tt, lit, seg, tkind, meta, nspan, nn, sbuf,
                                                            soff, ns, at)
                                    last, differs = tt, tdiff
                                    if tend >= 0:
                                        for tj in range(tk, 0, -1):
                                            order[tj] = order[tj - 1]
                                        order[0] = tt
                                        tm = meta[tt]
                                        if items.shape[0] < ni + tm[M_ITEMS]:
                                            items = _grow(items, ni + tm[M_ITEMS])
                                        if ext.shape[0] < ne + tm[M_EXT]:
                                            ext = _grow(ext, ne + tm[M_EXT])
                                        rows(tt, nb, nn, ns, titems, text, meta, items, ni, ext, ne)
                                        cub_first = nn + tm[M_CUB]
                                        ni += tm[M_ITEMS]
                                        ne += tm[M_EXT]
                                        nn += tm[M_NUMS]
                                        ns += tm[M_STRS]
                                        hint = tm[M_HINT]
                                        i = tend
                                        matched += 1
                                        break
                                if tend < 0:  # (the parser reads it, and it becomes a template)
                                    nn0, ns0, ni0, ne0 = nn, ns, ni, ne
                                    deepest = max(deepest, 5)
                                    i = _ws(b, i + 1)
                                    if b[i] != 34:
                                        return fail
                                    i = _key(b, i, _OBJECT_DATA)
                                    if i < 0:
                                        return fail
                                    i = _colon(b, i)
                                    if i < 0:
                                        return fail
                                    if b[i] != 123:
                                        return fail
                                    i = _ws(b, i + 1)
                                    seen = 0
                                    ncub = 0
                                    cub_first = -1
                                    if b[i] == 125:
                                        return fail  # (no cuboid)
                                    while True:  # object_data's members: the kinds
                                        if b[i] != 34:
                                            return fail
                                        kind = K_VEC
                                        e = _key(b, i, _KIND_VEC)
                                        if e < 0:
                                            kind = K_NUM
                                            e = _key(b, i, _KIND_NUM)
                                        if e < 0:
                                            kind = K_TEXT
                                            e = _key(b, i, _KIND_TEXT)
                                        if e < 0:
                                            kind = K_BOOLEAN
                                            e = _key(b, i, _KIND_BOOLEAN)
                                        if e < 0:
                                            kind = K_CUBOID
                                            e = _key(b, i, _KIND_CUBOID)
                                        if e < 0:
                                            return fail
                                        i = e
                                        if seen & (1 << kind):
                                            return fail
                                        seen |= 1 << kind
                                        i = _colon(b, i)
                                        if i < 0:
                                            return fail
                                        if b[i] != 91:
                                            return fail
                                        deepest = max(deepest, 6)
                                        i = _ws(b, i + 1)
                                        if b[i] == 93:
                                            i += 1
                                        else:
                                            while True:  # the items: {"name": ..., "val": ..., ...}
                                                if b[i] != 123:
                                                    return fail
                                                deepest = max(deepest, 7)
                                                i = _ws(b, i + 1)
                                                name = -1
                                                has_val = False
                                                val = 0
                                                count = 0
                                                if b[i] == 125:
                                                    return fail
                                                while True:  # the item's members
                                                    if b[i] != 34:
                                                        return fail
                                                    member = 2
                                                    e = _key(b, i, _NAME)
                                                    if e < 0:
                                                        member = 3
                                                        e = _key(b, i, _VAL)
                                                    if e < 0:
                                                        ks = i
                                                        e, esc = _string(b, i, n)
                                                        if e < 0:
                                                            return fail
                                                        member = 1 if not esc and _eq(b, ks + 1, e - 1, _EXT) else 0
                                                    i = _colon(b, e)
                                                    if i < 0:
                                                        return fail
                                                    if member == 2:
                                                        if name >= 0 or b[i] != 34:
                                                            return fail
                                                        if kind == K_CUBOID:
                                                            i = _key(b, i, _BOUNDING_BOX)
                                                            if i < 0:
                                                                return fail
                                                            name = 0
                                                        else:
                                                            e = _known(b, i, tbuf, toff, hint + 1, nt)
                                                            if e >= 0:
                                                                name = hint = hint + 1
                                                                i = e
                                                            else:
                                                                s = i
                                                                i, esc = _string(b, i, n)
                                                                if i < 0 or esc:
                                                                    return fail
                                                                name, tbuf, toff, nt = _intern(b, s + 1, i - 1, tbuf,
                                                                                               toff, nt, hint + 1)
                                                                hint = name
                                                    elif member == 3:
                                                        if has_val:
                                                            return fail
                                                        has_val = True
                                                        if kind == K_VEC or kind == K_CUBOID:
                                                            if b[i] != 91:
                                                                return fail
                                                            deepest = max(deepest, 8)
                                                            val = nn
                                                            i = _ws(b, i + 1)
                                                            if b[i] == 93:
                                                                i += 1
                                                            else:
                                                                while True:
                                                                    e = _number(b, i)
                                                                    if e < 0:
                                                                        return fail
                                                                    nspan = _span(i, e, nspan, nn)
                                                                    nn += 1
                                                                    i, more = _next(b, e, 93)
                                                                    if more < 0:
                                                                        return fail
                                                                    if more == 0:
                                                                        break
                                                            count = nn - val
                                                        elif kind == K_NUM:
                                                            e = _number(b, i)
                                                            if e < 0:
                                                                return fail
                                                            nspan = _span(i, e, nspan, nn)
                                                            val = nn
                                                            nn += 1
                                                            i = e
                                                        elif kind == K_TEXT:
                                                            if b[i] != 34:
                                                                return fail
                                                            s = i
                                                            i, esc = _string(b, i, n)
                                                            if i < 0 or esc:
                                                                return fail
                                                            sbuf, soff = _put(b, s + 1, i - 1, sbuf, soff, ns)
                                                            sspan = _span(s, i, sspan, ns)
                                                            val = ns
                                                            ns += 1
                                                        else:
                                                            e = _literal(b, i, _TRUE)
                                                            val = 1
                                                            if e < 0:
                                                                e = _literal(b, i, _FALSE)
                                                                val = 0
                                                            if e < 0:
                                                                return fail
                                                            i = e
                                                    elif kind == K_CUBOID:
                                                        if member != 1 or b[i] != 123:
                                                            return fail  # (coordinate_system, attributes...)
                                                        deepest = max(deepest, 8)
                                                        i = _ws(b, i + 1)
                                                        if b[i] == 125:
                                                            i += 1
                                                        else:
                                                            while True:  # the extension item: "key": scalar
                                                                if b[i] != 34:
                                                                    return fail
                                                                ext = _grow(ext, ne + 1)
                                                                ext[ne, 0] = nb
                                                                e = _known(b, i, tbuf, toff, hint + 1, nt)
                                                                if e >= 0:
                                                                    code = hint + 1
                                                                    i = e
                                                                else:
                                                                    s = i
                                                                    i, esc = _string(b, i, n)
                                                                    if i < 0 or esc:
                                                                        return fail
                                                                    code, tbuf, toff, nt = _intern(b, s + 1, i - 1,
                                                                                                   tbuf, toff, nt,
                                                                                                   hint + 1)
                                                                ext[ne, 1] = hint = code
                                                                i = _colon(b, i)
                                                                if i < 0:
                                                                    return fail
                                                                c = b[i]
                                                                if c == 34:
                                                                    s = i
                                                                    i, esc = _string(b, i, n)
                                                                    if i < 0 or esc:
                                                                        return fail
                                                                    sbuf, soff = _put(b, s + 1, i - 1, sbuf, soff, ns)
                                                                    sspan = _span(s, i, sspan, ns)
                                                                    ext[ne, 2] = E_STR
                                                                    ext[ne, 3] = ns
                                                                    ns += 1
                                                                elif c == 116:
                                                                    i = _literal(b, i, _TRUE)
                                                                    ext[ne, 2] = E_TRUE
                                                                    ext[ne, 3] = 0
                                                                elif c == 102:
                                                                    i = _literal(b, i, _FALSE)
                                                                    ext[ne, 2] = E_FALSE
                                                                    ext[ne, 3] = 0
                                                                else:
                                                                    e, fl = _number_kind(b, i)
                                                                    if e < 0:
                                                                        return fail  # (null, a list...)
                                                                    nspan = _span(i, e, nspan, nn)
                                                                    ext[ne, 2] = E_FLOAT if fl else E_INT
                                                                    ext[ne, 3] = nn
                                                                    nn += 1
                                                                    i = e
                                                                if i < 0:
                                                                    return fail
                                                                ne += 1
                                                                i, more = _next(b, i, 125)
                                                                if more < 0:
                                                                    return fail
                                                                if more == 0:
                                                                    break
                                                    else:  # another member of an attribute: not read
                                                        i, d = _skip(b, i, n)
                                                        if i < 0:
                                                            return fail
                                                        deepest = max(deepest, 7 + d)
                                                    i, more = _next(b, i, 125)
                                                    if more < 0:
                                                        return fail
                                                    if more == 0:
                                                        break
                                                if name < 0 or not has_val:
                                                    return fail
                                                if kind == K_CUBOID:
                                                    ncub += 1
                                                    cub_first = val
                                                    if count != 9:
                                                        return fail
                                                else:
                                                    items = _grow(items, ni + 1)
                                                    items[ni, 0] = nb
                                                    items[ni, 1] = kind
                                                    items[ni, 2] = name
                                                    items[ni, 3] = val
                                                    items[ni, 4] = count
                                                    ni += 1
                                                i, more = _next(b, i, 93)
                                                if more < 0:
                                                    return fail
                                                if more == 0:
                                                    break
                                        i, more = _next(b, i, 125)
                                        if more < 0:
                                            return fail
                                        if more == 0:
                                            break
                                    i = _ws(b, i)
                                    if b[i] != 125 or ncub != 1:  # (another member of the box; no or 2 cuboids)
                                        return fail
                                    i += 1
                                    if not use_templates:
                                        pass
                                    elif no_build > 0:
                                        no_build -= 1
                                    elif build(b, box_start, i, nn0, nn, nspan, ns0, ns, sspan, items, ni0, ni, ext,
                                               ne0, ne, cub_first, hint, lit, seg, tkind, titems, text, meta,
                                               order, common):
                                        built += 1
                                        if built >= GIVE_UP_AFTER_BUILDS and matched < built:
                                            use_templates = False
                                    else:
                                        no_build = NO_BUILD_AFTER_FAILURE
                                boxes = _grow(boxes, nb + 1)
                                boxes[nb, 0] = box_start
                                boxes[nb, 1] = i
                                boxes[nb, 2] = cub_first
                                nb += 1
                                # ---- the next box or the end of the objects
                                i, more = _next(b, i, 125)
                                if more < 0:
                                    return fail
                                if more == 0:
                                    break
                    i, more = _next(b, i, 125)
                    if more < 0:
                        return fail
                    if more == 0:
                        break
            i, more = _next(b, i, 125)
            if more < 0:
                return fail
            if more == 0:
                break
    if _ws(b, i) != n:
        return fail
    nbuf, noff = _gather(b, nspan, nn, nbuf, noff)
    return (0, deepest, nb, ni, ne, nn, ns, nt, boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff, nspan,
            sspan)


@_jit_loop
def skeleton(b, boxes):
    """The block ``b`` (its bytes, without the NUL) with each box (spans ``boxes[:, :2]``, in
    order) replaced by its row number: what orjson parses for the frames around the boxes."""
    n = b.size
    size = n
    for r in range(boxes.shape[0]):
        size -= boxes[r, 1] - boxes[r, 0]
        d = 1
        v = r
        while v >= 10:
            v //= 10
            d += 1
        size += d
    out = np.empty(size, np.uint8)
    o = 0
    prev = 0
    for r in range(boxes.shape[0]):
        s = boxes[r, 0]
        out[o:o + s - prev] = b[prev:s]
        o += s - prev
        d = 1
        v = r
        while v >= 10:
            v //= 10
            d += 1
        v = r
        for k in range(d - 1, -1, -1):
            out[o + k] = 48 + v % 10
            v //= 10
        o += d
        prev = boxes[r, 1]
    out[o:] = b[prev:n]
    return out


@_jit_loop
def first_items(items, slot_of_code, want_kind, n):
    """``(first, mixed)``: per slot (``slot_of_code``: the slot of each name code, -1: none) and
    box the row in ``items`` of the first item of the slot's name — of the earliest kind in
    :data:`KINDS`' order, the first of them (as the profile's reader takes attributes) — or -1;
    ``mixed``: an item of a slot's name in another kind than ``want_kind`` of the slot (>= 0)."""
    first = np.full((want_kind.size, n), -1, np.int64)
    for r in range(items.shape[0]):
        s = slot_of_code[items[r, 2]]
        if s < 0:
            continue
        k = items[r, 1]
        if want_kind[s] >= 0 and k != want_kind[s]:
            return first, True
        b = items[r, 0]
        f = first[s, b]
        if f < 0 or k < items[f, 1]:
            first[s, b] = r
    return first, False
