"""georef: lenient reading of real-world geoReference strings, local <-> WGS 84, header offsets."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aveas_format.errors import FormatError
from aveas_format.crs import GeoReferenceWarning, LocalFrame, crs_equal, parse_crs

TMERC = "+proj=tmerc +lat_0=49 +lon_0=8 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def test_carla_string_without_proj_is_a_tmerc_at_the_origin():
    p = parse_crs("+lat_0=4.9000000000000000e+1 +lon_0=8.0000000000000000e+0")
    assert p.lenient and "no +proj" in p.notes[0]
    assert crs_equal("+lat_0=4.9000000000000000e+1 +lon_0=8.0000000000000000e+0", TMERC)
    with pytest.warns(GeoReferenceWarning, match="transverse Mercator"):
        frame = LocalFrame("+lat_0=49 +lon_0=8")
    lon, lat = frame.to_wgs84(np.array([0.0]), np.array([0.0]))
    assert lon[0] == pytest.approx(8.0) and lat[0] == pytest.approx(49.0)


def test_utm_without_zone_is_read_at_its_origin():
    p = parse_crs("+proj=utm +lat_0=37.35 +lon_0=-122.08 +datum=WGS84")
    assert p.lenient and "without +zone" in p.notes[0]
    lon, lat = LocalFrame("+proj=utm +lat_0=37.35 +lon_0=-122.08", warn=False).to_wgs84(
        np.array([0.0]), np.array([0.0]))
    assert lon[0] == pytest.approx(-122.08) and lat[0] == pytest.approx(37.35)


def test_missing_vertical_grid_is_dropped_with_a_note():
    # the e6mini string: a UTM zone plus a geoid grid file PROJ does not have here
    text = ("+proj=utm +lat_0=37.35429341239328 +lon_0=-122.0859797650754 +k_0=1 +x_0=0 +y_0=0 "
            "+datum=WGS84 +geoidgrids=egm96_15.gtx +vunits=m +zone=32 +ellps=GRS80 +units=m +no_defs")
    p = parse_crs(text)
    assert any("+geoidgrids" in n for n in p.notes)
    LocalFrame(text, warn=False).to_wgs84(np.array([500000.0]), np.array([0.0]))


@pytest.mark.parametrize("text", ["", "   ", "+ellps=WGS84", "+proj=nonsense +lat_0=1", "+proj=utm +datum=WGS84",
                                  "+lat_0=4:.9 +lon_0=8", "+oj=tmerc +lat_0=4:.9"])
def test_unreadable_strings_are_clear_errors(text):
    with pytest.raises(FormatError):
        parse_crs(text)


def test_cdata_wrapping_and_epsg():
    assert parse_crs("<![CDATA[ " + TMERC + " ]]>").text == TMERC
    assert parse_crs("EPSG:25832").crs.to_epsg() == 25832


@settings(max_examples=100, deadline=None)
@given(x=st.floats(-5000, 5000), y=st.floats(-5000, 5000), ox=st.floats(-1e5, 1e5),
       oy=st.floats(-1e5, 1e5), hdg=st.floats(-3.1, 3.1))
def test_round_trip_with_header_offset(x, y, ox, oy, hdg):
    frame = LocalFrame(TMERC, offset=(ox, oy, 0.0, hdg))
    lon, lat = frame.to_wgs84(np.array([x]), np.array([y]))
    bx, by = frame.from_wgs84(lon, lat)
    assert abs(bx[0] - x) < 1e-5 and abs(by[0] - y) < 1e-5


def test_offset_convention_rotate_then_translate():
    frame = LocalFrame(TMERC, offset=(100.0, 200.0, 0.0, np.pi / 2))
    px, py = frame.to_projected(np.array([10.0]), np.array([0.0]))
    assert px[0] == pytest.approx(100.0) and py[0] == pytest.approx(210.0)
