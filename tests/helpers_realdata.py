"""Helpers of the real-file suite (tests/realdata/): the files other tools wrote, under ../shared/data.

One test module per source kind (``tests/realdata/test_<kind>.py``) parametrises over every
matching file with :func:`real_files`; without ``../shared`` beside the checkout each such test is
skipped with one reason.
"""

from __future__ import annotations

import pytest

from helpers_common import SHARED

DATA = SHARED / "data"
REAL = DATA / "real"
ABSENT = f"real-file suite: the shared data folder is not at {DATA} (clone ../shared beside the checkout)"


def real_files(*patterns: str) -> list:
    """``pytest.param(path, id=...)`` for every file under ``../shared/data`` matching one of the
    glob ``patterns`` (relative to ``../shared/data``), sorted; one skipped param when the folder is
    absent, so that parametrised tests report one clear reason."""
    if not DATA.is_dir():
        return [pytest.param(None, id="shared-data-absent", marks=pytest.mark.skip(reason=ABSENT))]
    paths = sorted({p for pat in patterns for p in DATA.glob(pat) if p.is_file()})
    return [pytest.param(p, id=str(p.relative_to(DATA))) for p in paths]


#: a transverse Mercator for maps without a geoReference (the files' site is unknown: a CRS must
#: be given, FORMAT.md; where on Earth does not matter for these checks)
SOME_CRS = "+proj=tmerc +lat_0=57.7 +lon_0=11.97 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def crs_for(map_path) -> str | None:
    """``SOME_CRS`` where the map has no ``<geoReference>``, else None (the map's counts)."""
    from aveas_format.opendrive import load_map

    return None if load_map(map_path).header.geo_reference else SOME_CRS


def round_trips(rec, out_dir):
    """``{format: recording}``: ``rec`` exported to OpenLABEL, OpenSCENARIO (every sample) and OSI
    and imported back, each with the map its export wrote next to it (the recording's ``crs`` has to
    travel with it where the map has no geoReference)."""
    import warnings

    from aveas_format.converters.registry import convert, get_converter

    back = {}
    for name, file, opts in (("openlabel", "rt.json", {}),
                             ("openscenario", "rt.xosc", {"max_rate_hz": None}),
                             ("osi", "rt.osi", {})):
        d = out_dir / name
        d.mkdir(parents=True, exist_ok=True)
        paths = get_converter(name, "export")(rec, d / file, options=opts)
        assert (d / "rt.xodr") in paths, paths  # the map travels with every export
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            back[name] = convert(name, [d / file],
                                 map_source=None if name == "openscenario" else d / "rt.xodr")
    return back


def assert_same_motion(rec, back, *, tol_m: float = 1e-3) -> None:
    """The re-imported recording has the same participants (ids and classes), and each one the
    positions of its source at its own times (to ``tol_m``; times shifted where an export starts
    its clock at the first sample)."""
    import numpy as np
    import pyarrow.compute as pc

    assert back.participants.column("participant_id").to_pylist() == \
        rec.participants.column("participant_id").to_pylist()
    assert back.participants.column("class").to_pylist() == rec.participants.column("class").to_pylist()
    shift = float(pc.min(rec.states["time"]).as_py()) - float(pc.min(back.states["time"]).as_py())
    for q in rec.participants.column("participant_id").to_pylist():
        a = rec.states.filter(pc.equal(rec.states["participant_id"], q))
        b = back.states.filter(pc.equal(back.states["participant_id"], q))
        assert b.num_rows, q
        tb = b["time"].to_numpy() + shift
        for c in ("x", "y"):
            ref = np.interp(tb, a["time"].to_numpy(), a[c].to_numpy())
            assert np.max(np.abs(b[c].to_numpy() - ref)) < tol_m, (q, c)
