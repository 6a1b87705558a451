"""Recording -> ASAM OSI trace (the export; the import and the trace format: :mod:`aveas_format.
converters.osi`).

A GroundTruth per time step (every ``every``-th), its moving objects built from the states'
columns a batch of :data:`BATCH_STATES` at a time and encoded as the bindings encode them
(:func:`encode_ground_truths`); written as a binary ``.osi`` trace or an MCAP trace with the
``net.asam.osi.trace`` metadata and a record of the recording's partner, rights, start time and
title, the map next to it (named in every ``map_reference``).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from pydantic import Field

from aveas_format.converters import _protowire as pw
from aveas_format.converters.common.companion import companion_map_path, write_companion_map
from aveas_format.converters.osi import CARRIED_RECORD
from aveas_format.converters.registry import ConverterOptions, converter
from aveas_format.errors import FormatError
from aveas_format.io.arrow import column_numpy

#: class -> (OSI MovingObject type, vehicle classification type or None)
EXPORT_CLASS: dict[str, tuple[str, str | None]] = {
    "car": ("VEHICLE", "MEDIUM_CAR"), "van": ("VEHICLE", "DELIVERY_VAN"),
    "truck": ("VEHICLE", "HEAVY_TRUCK"), "trailer": ("VEHICLE", "TRAILER"),
    "bus": ("VEHICLE", "BUS"), "motorcycle": ("VEHICLE", "MOTORBIKE"),
    "bicycle": ("VEHICLE", "BICYCLE"), "railvehicle": ("VEHICLE", "TRAM"),
    "mobility_device": ("VEHICLE", "MICROMOBILITY_DEVICE"), "pedestrian": ("PEDESTRIAN", None),
    "animal": ("ANIMAL", None), "pushable_pullable": ("OTHER", None), "other": ("OTHER", None),
}


class OsiExportOptions(ConverterOptions):
    host_id: int | None = None
    """Participant that becomes the GroundTruth's host vehicle (default: the first participant with
    role system_under_test or recording_vehicle, else none)."""
    every: int = Field(1, ge=1)
    """Write every n-th time step (1 = all)."""
    map_file: str | None = None
    """File name of the map written next to the trace (default: the trace's name with .xodr)."""
    write_map: bool = True
    """Write the map next to the trace (with the recording's crs as its geoReference where the map
    has none); every GroundTruth's ``map_reference`` names it, so that the trace re-imports
    without ``--map``."""


def _light_state(b, brake: float, left: float, right: float, hazard: float):
    def on(p: float) -> bool:
        return bool(np.isfinite(p) and p >= 0.5)

    ind = ("WARNING" if on(hazard) else "LEFT" if on(left) else "RIGHT" if on(right) else
           "OFF" if np.isfinite(left) or np.isfinite(right) or np.isfinite(hazard) else "UNKNOWN")
    brk = "NORMAL" if on(brake) else "OFF" if np.isfinite(brake) else "UNKNOWN"
    return b.MovingObjectVehicleClassificationLightState(
        indicator_state=getattr(b.MovingObjectVehicleClassificationLightStateIndicatorState, ind),
        brake_light_state=getattr(b.MovingObjectVehicleClassificationLightStateBrakeLightState, brk))


#: states encoded at once by the OSI export (bounds its memory: ~1 kB per state while encoding)
BATCH_STATES = 25_000

#: heights (m) where a participant has none
_DEFAULT_HEIGHT = {"pedestrian": 1.75, "bicycle": 1.7, "truck": 3.5, "bus": 3.2, "trailer": 3.5}


def encode_ground_truths(b, participants, order: np.ndarray, bounds: np.ndarray, sec: np.ndarray,
                         nanos: np.ndarray, host: int | None, proj_string: str, *, pid, x, y,
                         heading, vx, vy, ax, ay, lights, map_reference: str = "") -> pw.Ragged:
    """The serialized ``osi3.GroundTruth`` of each time step, from columns (:mod:`._protowire`):
    the states ``order[bounds[k]:bounds[k+1]]`` are the moving objects of step ``k`` (timestamp
    ``sec[k]``, ``nanos[k]``). Field for field what the bindings' messages held (the module
    docstring of :func:`export_osi`); ``lights`` (brake, left, right, hazard probabilities) or
    None."""
    p = participants
    p_ids = p.column("participant_id").to_numpy()
    by_id = np.argsort(p_ids)
    row = by_id[np.searchsorted(p_ids, pid[order], sorter=by_id)]
    classes = p.column("class").cast("string").to_pylist()
    heights = (p.column("height").to_pylist() if "height" in p.column_names else [None] * len(classes))
    h_p = np.array([hh or _DEFAULT_HEIGHT.get(c, 1.5) for hh, c in zip(heights, classes)], float)
    mtype = b.MovingObjectType
    vtypes = b.MovingObjectVehicleClassificationType
    kinds = [EXPORT_CLASS.get(c, ("OTHER", None)) for c in classes]
    otype_p = np.array([int(getattr(mtype, o)) for o, _ in kinds], np.int64)
    vtype_p = np.array([int(getattr(vtypes, v)) if v else -1 for _, v in kinds], np.int64)
    L = column_numpy(p, "length")[row]
    W = column_numpy(p, "width")[row]
    H = h_p[row]
    o = order

    def vec(a, bb, c):
        return pw.concat(pw.f_double(1, a), pw.f_double(2, bb), pw.f_double(3, c))

    zeros = np.zeros(len(o))
    acc_ok = np.isfinite(ax[o])
    base = pw.concat(
        pw.f_message(1, vec(L, W, H)),                                 # dimension
        pw.f_message(2, vec(x[o], y[o], H / 2)),                       # position
        pw.f_message(3, pw.f_double(3, heading[o])),                   # orientation.yaw
        pw.f_message(4, vec(vx[o], vy[o], zeros)),                     # velocity
        pw.keep(pw.f_message(5, vec(np.where(acc_ok, ax[o], 0.0), np.where(acc_ok, ay[o], 0.0),
                                    zeros)), acc_ok))                  # acceleration
    vt = vtype_p[row]
    is_vehicle = vt >= 0
    vc = [pw.f_varint(1, np.maximum(vt, 0))]
    if lights is not None:
        brake, left, right, hazard = (v[o] for v in lights)

        def on(v):
            return np.isfinite(v) & (v >= 0.5)

        ind_s = b.MovingObjectVehicleClassificationLightStateIndicatorState
        brk_s = b.MovingObjectVehicleClassificationLightStateBrakeLightState
        known = np.isfinite(left) | np.isfinite(right) | np.isfinite(hazard)
        ind = np.select([on(hazard), on(left), on(right), known],
                        [int(ind_s.WARNING), int(ind_s.LEFT), int(ind_s.RIGHT), int(ind_s.OFF)],
                        int(ind_s.UNKNOWN))
        brk = np.select([on(brake), np.isfinite(brake)], [int(brk_s.NORMAL), int(brk_s.OFF)],
                        int(brk_s.UNKNOWN))
        vc.append(pw.f_message(2, pw.concat(pw.f_varint(1, ind), pw.f_varint(7, brk))))
    mo = pw.concat(
        pw.f_message(1, pw.f_varint(1, pid[o])),                       # id
        pw.f_message(2, base),
        pw.f_varint(3, otype_p[row]),                                  # type
        pw.keep(pw.f_message(6, pw.concat(*vc)), is_vehicle))          # vehicle_classification
    m = len(sec)
    parts = [pw.f_message(2, pw.concat(pw.f_varint(1, sec), pw.f_varint(2, nanos)))]  # timestamp
    if host is not None:
        parts.append(pw.Ragged.const(pw.f_message(3, pw.f_varint(1, np.array([host]))).data.tobytes(),
                                     m))                                # host_vehicle_id
    parts.append(pw.group(pw.f_message(5, mo), bounds))                # moving_object
    if proj_string:
        parts.append(pw.Ragged.const(pw.f_strings(14, [proj_string]).data.tobytes(), m))
    if map_reference:  # the map's file name, next to the trace
        parts.append(pw.Ragged.const(pw.f_strings(15, [map_reference]).data.tobytes(), m))
    return pw.concat(*parts)


class _Encoded:
    """A serialized GroundTruth as betterosi's writer takes a message (its type for the MCAP
    channel's schema, its bytes)."""

    def __init__(self, raw: bytes, proto) -> None:
        self.raw, self.proto = raw, proto

    def desc(self):
        return self.proto.desc()

    def to_binary(self) -> bytes:
        return self.raw


@converter("osi", direction="export", options=OsiExportOptions,
           description="ASAM OSI GroundTruth trace (.osi length-prefixed binary, or .mcap)",
           requires=("betterosi",), extra="osi")
def export_osi(rec, output: Path, *, options: OsiExportOptions) -> list[Path]:
    """One ``osi3.GroundTruth`` per distinct ``time``: every participant present then as a moving
    object (id = participant_id; base position = footprint centre with z = half the height, yaw =
    heading, velocity, acceleration where the states or derived kinematics have it, dimension;
    type and vehicle classification from the class; brake and indicator lights where the states
    carry their probabilities, on at >= 0.5), ``proj_string`` = the recording's CRS, and the host
    vehicle. Timestamps are the recording's ``time`` (s); an MCAP trace carries ``zero_time`` =
    ``start_time``. The map is written next to the trace (``write_map``, ``map_file``; OSI
    references it, does not embed it), with the recording's ``crs`` as its ``<geoReference>`` where
    the map has none. ``.osi`` or ``.mcap`` by the output's suffix."""
    import os

    import betterosi as b

    from aveas_format.converters.common.carried import carried_meta
    from aveas_format.safeio import write_chunks_atomic

    suffix = output.suffix.lower()
    if suffix not in (".osi", ".mcap"):
        raise FormatError("the OSI export writes .osi or .mcap (by the output's suffix)", path=output)
    st = rec.states
    n = st.num_rows
    companion = companion_map_path(output, options)
    map_name = companion.name if companion is not None else (options.map_file or "")

    pid = st["participant_id"].to_numpy()
    t = column_numpy(st, "time")
    # a null or absent value: NaN, or 0 for the heading and velocity
    x, y, ax, ay = (column_numpy(st, c, missing=math.nan) for c in ("x", "y", "ax", "ay"))
    heading, vx, vy = (column_numpy(st, c, null=0.0, missing=0.0) for c in ("heading", "vx", "vy"))
    kin = rec.derived.get("kinematics")
    if (kin is not None and np.isnan(ax).all() and kin.num_rows == n
            and np.array_equal(kin["participant_id"].to_numpy(), pid)
            and np.array_equal(kin["time"].to_numpy(zero_copy_only=False), t)):  # row-aligned
        ax, ay = column_numpy(kin, "ax"), column_numpy(kin, "ay")
    lights = [column_numpy(st, c, missing=math.nan) for c in
              ("light_brake_p", "light_indicator_left_p", "light_indicator_right_p", "light_hazard_p")]
    has_lights = any(np.isfinite(v).any() for v in lights)
    parts = rec.participants.to_pylist()
    info = {p["participant_id"]: p for p in parts}
    host = options.host_id
    if host is None:
        host = next((p["participant_id"] for p in parts
                     if p.get("role") in ("system_under_test", "recording_vehicle")), None)
    elif host not in info:
        raise FormatError(f"host_id {host}: no such participant", path=output)
    times = np.unique(t)[::options.every]
    sel = np.flatnonzero(np.isin(t, times)) if options.every > 1 else np.arange(n)
    order = sel[np.lexsort((pid[sel], t[sel]))]
    bounds = np.r_[np.searchsorted(t[order], times), len(order)]
    sec, nanos = np.divmod(np.round(times * 1e9).astype(np.int64), 10**9)

    def batches():
        """(GroundTruth bytes, step indices) of batches of about :data:`BATCH_STATES` states:
        the memory of the encoding stays bounded whatever the length of the recording."""
        k0 = 0
        while k0 < len(times):
            k1 = int(np.searchsorted(bounds, bounds[k0] + BATCH_STATES, side="right"))
            k1 = min(max(k1 - 1, k0 + 1), len(times))
            yield encode_ground_truths(
                b, rec.participants, order[bounds[k0]:bounds[k1]], bounds[k0:k1 + 1] - bounds[k0],
                sec[k0:k1], nanos[k0:k1], host, rec.meta.crs or "", pid=pid, x=x, y=y,
                heading=heading, vx=vx, vy=vy, ax=ax, ay=ay,
                lights=lights if has_lights else None, map_reference=map_name), range(k0, k1)
            k0 = k1

    extra = ([write_companion_map(rec, companion)]
             if companion is not None and rec.map_source is not None else [])
    if suffix == ".osi":
        return [write_chunks_atomic(output, (pw.length_prefixed(g) for g, _ in batches())),
                *extra]
    tmp = output.with_name(f".{output.stem}.tmp-{os.getpid()}.mcap")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            with b.Writer(tmp, metadata={"zero_time": rec.meta.start_time,
                                         "description": f"aveas-format export of "
                                                        f"{rec.meta.recording_id}"}) as w:
                w.add_metadata(CARRIED_RECORD, {**carried_meta(rec),
                                                **({"map": map_name} if map_name else {})})
                proto = b.GroundTruth()
                for gts, steps in batches():
                    for raw, k in zip(gts.tolist(), steps):
                        w.add(_Encoded(raw, proto), log_time=int(sec[k]) * 10**9 + int(nanos[k]))
        with open(tmp, "rb") as f:
            os.fsync(f.fileno())
        os.replace(tmp, output)
    finally:
        tmp.unlink(missing_ok=True)
    return [output, *extra]
