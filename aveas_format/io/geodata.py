"""A recording as GeoDataFrames (geopandas, the optional extra ``[geo]``), with the CRS set.

>>> gdf = rec.to_geopandas()                  # states: one Point per row   # doctest: +SKIP
>>> gdf.to_crs(4326).total_bounds             # lon/lat bounds              # doctest: +SKIP
>>> rec.unobserved_geodataframe().plot()      # the regions not observed    # doctest: +SKIP

Positions are stored in the recording's local frame: its ``crs`` (recording.json) shifted and
rotated by the map header's ``<offset>`` (FORMAT.md 3). The geometries here are moved into the CRS
itself (:meth:`~aveas_format.crs.LocalFrame.to_projected`), so that ``gdf.crs`` is a plain
CRS that any GIS understands; the local ``x``/``y`` stay as columns. ``Recording.to_geopandas`` and
``Recording.unobserved_geodataframe`` call these functions (in ``io`` with the Recording: the
CRS reading they need, :mod:`aveas_format.crs`, lies below it).
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa

from aveas_format.errors import require
from aveas_format.crs import LocalFrame


def _frame(rec) -> LocalFrame:
    """The recording's frame: its CRS with the map header's offset (none without a map)."""
    offset = rec.map.header.offset if rec.map_source is not None else None
    return LocalFrame(rec.meta.crs, offset=offset, warn=False)


def _frame_of(table: pa.Table, skip: tuple[str, ...] = ()):
    """A pandas DataFrame of ``table`` (dictionary columns as categoricals, ints stay int64)."""
    cols = [c for c in table.column_names if c not in skip]
    return table.select(cols).to_pandas()


def states_geodataframe(rec, columns: list[str] | None = None, *, classes: bool = True):
    """The states as a GeoDataFrame: one Point per row in the recording's CRS (x/y placed in
    it), the columns of states.parquet (or ``columns``) and, with ``classes``, each participant's
    ``class``."""
    gpd = require("geopandas", extra="geo", what="to_geopandas")
    s = rec.states
    if s is None:
        raise ValueError("the recording has no states table")
    if columns is not None:
        missing = [c for c in columns if c not in s.column_names]
        if missing:
            raise KeyError(f"states has no column(s) {missing}; it has {s.column_names}")
        s = s.select(list(dict.fromkeys(["participant_id", "time", "x", "y", *columns])))
    df = _frame_of(s)
    p = rec.participants
    if classes and p is not None and p.num_rows and "class" in p.column_names:
        ids = np.asarray(p.column("participant_id").to_numpy(zero_copy_only=False), np.int64)
        cls = np.asarray(p.column("class").cast(pa.string()).to_pylist(), dtype=object)
        order = np.argsort(ids, kind="stable")
        pid = df["participant_id"].to_numpy(np.int64)
        pos = np.clip(np.searchsorted(ids[order], pid), 0, len(ids) - 1)
        found = ids[order][pos] == pid
        df.insert(1, "class", np.where(found, cls[order][pos], None))
        df["class"] = df["class"].astype("category")
    frame = _frame(rec)
    px, py = frame.to_projected(df["x"].to_numpy(np.float64), df["y"].to_numpy(np.float64))
    return gpd.GeoDataFrame(df, geometry=gpd.points_from_xy(px, py), crs=frame.parsed.crs)


def unobserved_geodataframe(rec):
    """The unobserved regions (unobserved.parquet) as a GeoDataFrame of polygons in the
    recording's CRS; an empty one (with the CRS) when the recording has none."""
    gpd = require("geopandas", extra="geo", what="unobserved_geodataframe")
    import shapely

    frame = _frame(rec)
    u = rec.unobserved
    if u is None or not u.num_rows:
        return gpd.GeoDataFrame({"region_id": np.zeros(0, np.int64)}, geometry=[],
                                crs=frame.parsed.crs)
    df = _frame_of(u, skip=("geometry",))
    geoms = shapely.from_wkb(np.asarray(u.column("geometry").to_pylist(), dtype=object))
    geoms = shapely.transform(geoms, lambda xy: np.column_stack(frame.to_projected(xy[:, 0],
                                                                                   xy[:, 1])))
    return gpd.GeoDataFrame(df, geometry=geoms, crs=frame.parsed.crs)


__all__ = ["states_geodataframe", "unobserved_geodataframe"]
