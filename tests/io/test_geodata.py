"""Recording.to_geopandas / unobserved_geodataframe: GeoDataFrames in the recording's CRS."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

import helpers_validate as vf

gpd = pytest.importorskip("geopandas", reason='geopandas not installed (pip install '
                          '"aveas-format[geo]")')

#: the test map with a header offset (shift + rotation): local x/y are not CRS coordinates
OFFSET_MAP = vf.MAP.replace("</geoReference>", '</geoReference>\n    <offset x="1500.0" '
                            'y="-800.0" z="0.0" hdg="0.3"/>')


@pytest.fixture(scope="module")
def rec():
    sc = vf.fresh()
    sc["map"] = OFFSET_MAP
    return vf.build(sc)


def test_states_are_points_in_the_crs_that_match_lon_lat(rec):
    g = rec.to_geopandas()
    assert isinstance(g, gpd.GeoDataFrame) and len(g) == rec.states.num_rows
    assert g.crs == pyproj.CRS.from_user_input(rec.meta.crs)
    # x/y stay local columns; the geometry is in the CRS (the offset applied)
    assert not np.allclose(g.geometry.x, g["x"])
    ll = g.to_crs(4326)
    assert np.allclose(ll.geometry.x, g["lon"], atol=1e-8)
    assert np.allclose(ll.geometry.y, g["lat"], atol=1e-8)
    assert list(g["class"].cat.categories) == ["car", "truck", "van"]
    assert str(g["participant_id"].dtype) == "int64"
    assert g.loc[g.participant_id == 2, "class"].unique().tolist() == ["truck"]


def test_columns_and_unobserved_regions(rec):
    g = rec.to_geopandas(columns=["vx"], classes=False)
    assert list(g.columns) == ["participant_id", "time", "x", "y", "vx", "geometry"]
    with pytest.raises(KeyError, match="speed"):
        rec.to_geopandas(columns=["speed"])
    u = rec.unobserved_geodataframe()
    assert len(u) == 1 and u.crs == g.crs and u["region_id"].tolist() == [0]
    assert u.geometry.iloc[0].geom_type == "Polygon"
    # the region is 50 m x 10.5 m in the local frame and stays so in the (conformal) CRS
    assert u.geometry.iloc[0].area == pytest.approx(50 * 10.5, rel=1e-9)
    # the local box (900..950, -10.5..0) rotated by 0.3 rad and shifted
    c, s = np.cos(0.3), np.sin(0.3)
    cx, cy = 925.0, -5.25
    centre = u.geometry.iloc[0].centroid
    assert (centre.x, centre.y) == pytest.approx((cx * c - cy * s + 1500, cx * s + cy * c - 800))


def test_no_unobserved_table_gives_an_empty_frame_with_the_crs():
    sc = vf.fresh()
    sc["unobserved"] = None
    u = vf.build(sc).unobserved_geodataframe()
    assert len(u) == 0 and u.crs is not None


def test_missing_geopandas_is_one_line_naming_the_extra(rec, monkeypatch):
    import builtins

    from aveas_format.errors import MissingDependencyError

    real = builtins.__import__

    def no_geopandas(name, *a, **kw):
        if name.split(".")[0] == "geopandas":
            raise ImportError("No module named 'geopandas'")
        return real(name, *a, **kw)

    monkeypatch.setattr(builtins, "__import__", no_geopandas)
    monkeypatch.delitem(__import__("sys").modules, "geopandas")
    with pytest.raises(MissingDependencyError) as e:
        rec.to_geopandas()
    assert str(e.value) == ('geopandas, an optional dependency for to_geopandas, is not installed: '
                            'pip install "aveas-format[geo]"')
    assert (e.value.module, e.value.extra) == ("geopandas", "geo")
    assert isinstance(e.value, ImportError)
