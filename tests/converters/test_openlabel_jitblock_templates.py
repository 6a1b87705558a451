"""Boxes read by template (issue 22, converters/openlabel/_jitblock.py: build, match): a block gives the compiled
parser's arrays exactly, byte for byte, with and without templates — on the sample export, on
boxes of a few shapes with random values, and where a box that starts like a template is broken
later (refused the same: status 1)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

pytest.importorskip("numba", reason="numba is not installed (the jit extra)")
pytest.importorskip("orjson")

import aveas_format.converters.openlabel.fastblock as fb  # noqa: E402
from aveas_format.converters.openlabel import _jitblock as jb  # noqa: E402

from helpers_converters import openlabel_blocks  # noqa: E402


@pytest.fixture(scope="module")
def blocks(tmp_path_factory):
    """The blocks of frames of a sample export, as the import cuts them."""
    return openlabel_blocks(tmp_path_factory.mktemp("jitblock_templates"), n_vehicles=12, duration_s=8.0, seed=3,
                            size=60_000)


def _arrays(buf: bytes, by_template: bool) -> tuple:
    """parse_block's result, the used part of each array."""
    r = jb.parse_block(fb.padded(buf), *jb.scratch(len(buf)), by_template)
    status, depth, nb, ni, ne, nn, ns, nt = r[:8]
    if status:
        return (status,)
    boxes, items, ext, nbuf, noff, sbuf, soff, tbuf, toff, _, _ = r[8:]
    return (status, depth, boxes[:nb].tolist(), items[:ni].tolist(), ext[:ne].tolist(),
            nbuf[:noff[nn]].tobytes(), noff[:nn + 1].tolist(), sbuf[:soff[ns]].tobytes(),
            soff[:ns + 1].tolist(), tbuf[:toff[nt]].tobytes(), toff[:nt + 1].tolist())


def _same_both_ways(buf: bytes) -> tuple:
    want, got = _arrays(buf, False), _arrays(buf, True)
    assert got == want
    return got


def test_the_sample_export_reads_the_same_by_template(blocks):
    assert len(blocks) > 3
    for buf in blocks:
        assert _same_both_ways(buf)[0] == 0


def _matched(buf: bytes) -> tuple[int, int]:
    """``(boxes, of them read by a template)`` of the block: the parser's first box of each shape
    made a template (as parse_block does it), each later box matched against those."""
    r = jb.parse_block(fb.padded(buf), *jb.scratch(len(buf)), False)
    b = fb.padded(buf)
    status, _, nb, ni, ne, nn, ns, _ = r[:8]
    assert status == 0
    boxes, items, ext, nbuf, noff, sbuf, soff = r[8:15]
    nspan, sspan = r[17], r[18]
    nbox = np.searchsorted(items[:ni, 0], np.arange(nb + 1))
    ebox = np.searchsorted(ext[:ne, 0], np.arange(nb + 1))
    # each box's first number and string: its cuboid's first number; the strings counted by kind
    first_num = boxes[:nb, 2].copy()
    tpl = jb.templates()
    lit, seg, kind, titems, text, meta, order, common, at = tpl
    used = 0
    sb = np.zeros(nb + 1, np.int64)
    for k in range(nb):
        texts = items[nbox[k]:nbox[k + 1]]
        sb[k + 1] = sb[k] + int((texts[:, 1] == jb.K_TEXT).sum()) \
            + int((ext[ebox[k]:ebox[k + 1], 2] == jb.E_STR).sum())
    num_end = np.r_[first_num[1:], nn] if nb else first_num
    for k in range(nb):
        s, e = int(boxes[k, 0]), int(boxes[k, 1])
        hit = False
        for t in order[order >= 0]:
            end, _ = jb.match(b, s, 0, len(b) - 1, t, lit, seg, kind, meta, np.empty((jb.MAX_SLOTS, 2), np.int64),
                              0, np.empty(len(b), np.uint8), np.zeros(jb.MAX_SLOTS + 1, np.int64), 0, at)
            if end >= 0:
                assert end == e
                hit = True
                break
        used += hit
        if not hit:
            assert jb.build(b, s, e, first_num[k], num_end[k], nspan, sb[k], sb[k + 1], sspan, items, nbox[k],
                            nbox[k + 1], ext, ebox[k], ebox[k + 1], first_num[k], 0, lit, seg, kind, titems, text,
                            meta, order, common)
    return nb, used


def test_most_boxes_of_a_block_are_read_by_template(blocks):
    """The templates are what reads the sample's boxes: a few shapes, each parsed once."""
    nb, used = _matched(blocks[2])
    assert nb > 20 and used >= 0.8 * nb, (nb, used)


def _block(boxes: list[str], pretty: bool = False) -> bytes:
    sep = ", " if pretty else ","
    objs = sep.join('"%d":%s' % (k, b) for k, b in enumerate(boxes))
    return ('{"0":{"frame_properties":{"timestamp":0.0},"objects":{%s}}}' % objs).encode()


_NUMBER = st.one_of(
    st.integers(-10**6, 10**6).map(str),
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.sampled_from(["0.0", "-0.0", "-0", "1E+2", "0.5e-3", "12345678901234567890123", "1.0e400"]))
#: values a box may have in one place instead of a number (refused: status 1 with and without)
_BROKEN = st.sampled_from(["01", "1.", "-", ".5", "1e", "+1", "null", "true", '"1"', "1 2", "[1]"])
_TEXT = st.text(st.characters(min_codepoint=32, max_codepoint=126, exclude_characters='"\\'), max_size=6)
_BAD_TEXT = st.sampled_from(['a\\"b', "a\tb", "\\u0041", "\\q"])  # (an escape, a control: refused)


_SHAPE = st.tuples(st.booleans(), st.sampled_from(["true", "false"]), st.booleans(), st.sampled_from(["", " "]),
                   st.sampled_from([2, 6]), st.booleans())


@st.composite
def _boxes(draw) -> list[str]:
    """Boxes of two or three shapes per block (extension members present or not, true or false,
    vectors of two lengths, a text or none, compact or with spaces), the values random (all floats
    or any numbers), now and then one value broken."""
    shapes = draw(st.lists(_SHAPE, min_size=1, max_size=3))
    floats = draw(st.booleans())
    number = st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr) if floats else _NUMBER
    out = []
    n = draw(st.integers(2, 16))
    broken = draw(st.integers(0, 4 * n))  # (the box with a broken value, where < n)
    for k in range(n):
        has_vx, interpolated, has_note, sp, nvec, has_text = draw(st.sampled_from(shapes))
        nums = iter([draw(_BROKEN)] if k == broken else [])
        num = lambda: next(nums, None) or draw(number)  # noqa: E731
        ext = {"vx_std": num()}
        if has_vx:
            ext["vx"] = num()
        ext["interpolated"] = interpolated
        ext["source_frame"] = str(draw(st.integers(0, 10**6)))
        if has_note:
            ext["note"] = '"%s"' % draw(_BAD_TEXT if k == broken + 1 else _TEXT)
        cub = ",".join(num() for _ in range(9))
        ext_s = ",".join(f'"{k}":{sp}{v}' for k, v in ext.items())
        vec = ",".join(num() for _ in range(nvec))
        box = (f'{{"object_data":{{"cuboid":[{{"name":"bounding_box","val":[{cub}],"aveas_format":{{{ext_s}}}}}],'
               f'"vec":[{{"name":"velocity","val":[{vec}]}}],'
               f'"num":[{{"name":"open_drive/lane_position","val":{num()}}}]')
        if has_text:
            box += f',"text":[{{"name":"open_drive/lane_id","val":"{draw(_TEXT)}"}}]'
        out.append(box + "}}")
    return out


@settings(max_examples=300, deadline=None)
@given(_boxes(), st.booleans())
def test_boxes_of_a_few_shapes_read_the_same_by_template(boxes, pretty):
    got = _same_both_ways(_block(boxes, pretty))
    event("read" if got[0] == 0 else "refused")
    if got[0] == 0:
        nb, used = _matched(_block(boxes, pretty))
        event("boxes read by template: %d %%" % (100 * used // nb // 25 * 25))


_GOOD = ('{"object_data":{"cuboid":[{"name":"bounding_box","val":[1.5,2.5,0.75,0.0,0.0,0.1,4.5,1.8,1.5],'
         '"aveas_format":{"vx":12.5,"interpolated":false,"source_frame":3,"note":"x"}}],'
         '"vec":[{"name":"velocity","val":[12.5,0.5,0,0,0,0.01]}],"text":[{"name":"used_road_link","val":"1"}]}}')


@pytest.mark.parametrize("old, new", [
    ("12.5,0.5,0", "12.5,0.5,01"), ("0.01]", "0.01,]"), ("0.01]", "1.]"), ('"val":"1"', '"val":"1\\"x"'),
    ('"val":"1"', '"val":"a\tb"'), ('"val":"1"', '"val":"1'), ('"note":"x"', '"note":null'),
    ('"source_frame":3', '"source_frame":3.5'), ('"interpolated":false', '"interpolated":true'),
    ("0.01]}]", "0.01]}],"), ('"text"', '"tex"'), ("}}", "}"), ('"vx":12.5', '"vx":-'),
    ('4.5,1.8,1.5]', '4.5,1.8]')])
def test_a_box_that_starts_as_a_template_but_differs_later_is_read_as_the_parser_reads_it(old, new):
    """The first box makes the template; the second differs from it at one place: broken (both
    refuse it) or another shape (both read it the same)."""
    other = _GOOD.replace(old, new, 1)
    assert other != _GOOD
    for boxes in ([_GOOD, other], [_GOOD, _GOOD, other, _GOOD]):
        _same_both_ways(_block(boxes))


def test_a_long_number_or_text_grows_the_arrays_while_reading_by_template():
    long = _GOOD.replace("12.5,0.5", "12.5," + "1" * 5000, 1).replace('"val":"1"', '"val":"' + "y" * 5000 + '"')
    got = _same_both_ways(_block([_GOOD] * 3 + [long] * 3))
    assert got[0] == 0 and b"1" * 5000 in got[5] and b"y" * 5000 in got[7]


@pytest.mark.parametrize("shapes", [1, 3, 8, 9, 50])
def test_boxes_of_more_shapes_than_templates_read_the_same(shapes):
    """More shapes than templates (the least recently matched replaced; 9 in turn: none matches,
    and the templates are given up for the rest of the block), each box its own shape."""
    boxes = [_GOOD.replace('"note":"x"', f'"note":"x","k{k % shapes}":{k}') for k in range(150)]
    _same_both_ways(_block(boxes))


#: a box whose strings the cut cannot tell apart by their place: an extension member called
#: "name" (its string stored, though it follows a "name" key) and an item's member the parser
#: skips (its string not stored): as many strings as the parser stored, but not the same ones
_ODD = _GOOD.replace('"note":"x"', '"name":"n1"').replace('{"name":"velocity",', '{"name":"velocity","unit":"m/s",')


def test_a_box_whose_values_are_not_the_parser_s_is_no_template():
    _same_both_ways(_block([_ODD, _ODD.replace("n1", "n2").replace("m/s", "km/h"), _ODD]))


def test_a_template_given_up_halfway_is_not_used():
    """All templates in use, then a box that cannot be one (cut halfway into the least recently
    matched template's place), then boxes of that template's shape: read as the parser reads them."""
    shapes = [_GOOD.replace('"note":"x"', f'"note":"x","k{k}":{k}') for k in range(jb.TEMPLATES)]
    _same_both_ways(_block(shapes + [_ODD] + shapes + shapes[::-1]))
