"""Helpers of the real-file suite (tests/realdata/): the files other tools wrote, under ../shared/data.

One test module per source kind (``tests/realdata/test_<kind>.py``) parametrises over every
matching file with :func:`real_files`; each parameter carries the marker ``realdata``, and without
``../shared`` beside the checkout the test is skipped with the one reason
:data:`helpers_common.SHARED_ABSENT`.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from helpers_common import SHARED, SHARED_ABSENT, realdata_params

DATA = SHARED / "data"
REAL = DATA / "real"
ABSENT = SHARED_ABSENT


def real_files(*patterns: str) -> list:
    """``pytest.param(path, id=...)`` (marked ``realdata``) for every file under
    ``../shared/data`` matching one of the glob ``patterns`` (relative to ``../shared/data``),
    sorted; one skipped param when the folder is absent, so that parametrised tests report one
    clear reason."""
    paths = sorted({p for pat in patterns for p in DATA.glob(pat) if p.is_file()})
    return realdata_params(paths, ids=lambda p: str(p.relative_to(DATA)))


#: a transverse Mercator for maps without a geoReference (the files' site is unknown: a CRS must
#: be given, FORMAT.md; where on Earth does not matter for these checks)
SOME_CRS = "+proj=tmerc +lat_0=57.7 +lon_0=11.97 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"


def crs_for(map_path) -> str | None:
    """``SOME_CRS`` where the map has no ``<geoReference>``, else None (the map's counts)."""
    from aveas_format.opendrive import load_map

    return None if load_map(map_path).header.geo_reference else SOME_CRS


# --- the pieces every source kind's real-file test shares -----------------------------------------

#: small excerpts of third-party files committed with the tests (licences: tests/data/third_party/)
THIRD_PARTY = Path(__file__).parent / "data" / "third_party"


def third_party(*patterns: str) -> list:
    """``pytest.param(path, id=...)`` for the committed third-party excerpts matching ``patterns``."""
    paths = sorted({p for pat in patterns for p in THIRD_PARTY.glob(pat) if p.is_file()})
    return [pytest.param(p, id=f"third_party/{p.name}") for p in paths]


def error_codes(rec) -> set[str]:
    """The codes of the rules with error findings when ``rec`` is validated."""
    import aveas_format

    return {r.code for r in aveas_format.validate(rec).results if r.count and r.severity.value == "error"}


def round_trips(rec, tmp_path: Path, formats=("openlabel", "openscenario", "osi")) -> dict:
    """``rec`` exported to each format (OpenSCENARIO at every sample) and imported again:
    ``{format: recording}``, each with the map its export wrote next to it (the recording's ``crs``
    travels in that map where the map has no geoReference)."""
    import warnings

    from aveas_format.converters import convert, get_converter

    out = {}
    for fmt, name, opts in (("openlabel", "rt.json", {}), ("openscenario", "rt.xosc", {"max_rate_hz": None}),
                            ("osi", "rt.osi", {})):
        if fmt not in formats:
            continue
        d = tmp_path / fmt
        d.mkdir(parents=True, exist_ok=True)
        paths = get_converter(fmt, "export")(rec, d / name, options=opts)
        if rec.map_source is not None:
            assert (d / "rt.xodr") in paths, paths  # the map travels with every export
        kw = {}
        if fmt != "openscenario" and (d / "rt.xodr").exists():
            kw["map_source"] = d / "rt.xodr"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[fmt] = convert(fmt, [d / name], **kw)
    return out


def assert_same_trajectories(a, b, what: str, atol: float = 1e-6) -> None:
    """Same participants (count, classes) and the same positions after a round trip: every state
    that came back is one of the original's (times may start at 0 on the way back; an exporter may
    resample to a lower rate, as the OpenSCENARIO export does to 10 Hz), at its position."""
    assert b.participants.num_rows == a.participants.num_rows, what
    assert sorted(b.participants.column("class").to_pylist()) == \
        sorted(a.participants.column("class").to_pylist()), what

    def keyed(rec, ids=None):
        s = rec.states
        t = s.column("time").to_numpy()
        pid = s.column("participant_id").to_pylist()
        keys = zip([ids[q] for q in pid] if ids else pid, np.round(t - t.min(), 6).tolist())
        return dict(zip(keys, zip(s.column("x").to_numpy(), s.column("y").to_numpy())))

    # OSI numbers the participants anew and keeps the original id as source_id
    orig = set(a.participants.column("participant_id").to_pylist())
    back = dict(zip(b.participants.column("participant_id").to_pylist(),
                    b.participants.column("source_id").to_pylist()))
    renumbered = all(str(v).isdigit() and int(v) in orig for v in back.values()) and \
        set(back) != orig
    ka, kb = keyed(a), keyed(b, {k: int(v) for k, v in back.items()} if renumbered else None)
    assert set(kb) <= set(ka), f"{what}: states at times the original does not have"
    assert len(kb) == len(ka) or what.endswith("openscenario"), f"{what}: {len(kb)} of {len(ka)} states"
    err = max(np.hypot(ka[k][0] - kb[k][0], ka[k][1] - kb[k][1]) for k in kb)
    assert err <= atol, f"{what}: positions differ by up to {err} m"


def assert_plausible(rec, *, speed_quantile: float = 0.95, exempt: frozenset | set = frozenset()) -> None:
    """Sizes within the class's range and speeds below its limit (the validator's per-class
    table), for every participant whose class has them, except the ``exempt`` source ids (the
    source's own implausible objects, which the caller names)."""
    from aveas_format.validate.config import ValidationConfig

    limits = ValidationConfig().classes
    p = rec.participants
    for r in p.to_pylist():
        lim = limits.get(r["class"])
        if lim is None or r["source_id"] in exempt:
            continue
        for dim in ("length", "width"):
            rng = getattr(lim, dim)
            if rng is not None and r[dim] is not None:
                assert rng[0] <= r[dim] <= rng[1], (r["source_id"], r["class"], dim, r[dim], rng)
    s = rec.states
    if "vx" in s.column_names:
        speed = np.hypot(s.column("vx").to_numpy(zero_copy_only=False), s.column("vy").to_numpy(zero_copy_only=False))
        cls = dict(zip(p.column("participant_id").to_pylist(), p.column("class").to_pylist()))
        pid = s.column("participant_id").to_numpy()
        for q in np.unique(pid):
            lim = limits.get(cls[int(q)])
            if lim is not None and lim.speed_max is not None:
                v = np.nanquantile(speed[pid == q], speed_quantile)
                assert v <= lim.speed_max, (int(q), cls[int(q)], v)


# --- maps under the shared SUMO excerpts (written for them: the excerpts' networks are not shared) --

def sumo_excerpt_map(name: str) -> str:
    """OpenDRIVE text of a map under a SUMO excerpt of ../shared/data/sumo: ``cartesian`` a
    one-lane road along y = 401.65 westwards (the vehicle's road), ``geo`` a wide lane in a local
    frame centred on the geo excerpt's first sample (its road drifts 2 m north over 70 m)."""
    from aveas_format.opendrive.builder import straight_highway

    if name == "cartesian":
        return straight_highway(length=2000.0, lanes_right=1, x0=1600.0, y0=401.65 - 1.75, hdg=math.pi,
                                geo_reference="+proj=tmerc +lat_0=48.8 +lon_0=11.1 +k=1 +x_0=0 +y_0=0 "
                                "+ellps=WGS84 +units=m +no_defs")
    return straight_highway(length=1000.0, lanes_right=1, lane_width=6.0, x0=500.0, y0=-3.0, hdg=math.pi,
                            geo_reference="+proj=tmerc +lat_0=48.836229 +lon_0=11.090774 +k=1 +x_0=0 "
                            "+y_0=0 +ellps=WGS84 +units=m +no_defs")


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
