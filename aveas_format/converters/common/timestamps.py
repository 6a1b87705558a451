"""Timestamps of foreign files: their unit and epoch inferred, or given; ISO 8601 texts; Unix
nanoseconds as UTC text."""

from __future__ import annotations

import re
from collections.abc import Sequence
from datetime import datetime, timezone
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from typing import Any

import numpy as np

from aveas_format.errors import FormatError

#: ``timestamp_unit`` option values: ``auto`` infers the unit (see :func:`resolve_timestamps`)
TIMESTAMP_UNITS = ("auto", "s", "ms", "us", "ns")
_NS_PER = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_UNIT_WORD = {"s": "seconds", "ms": "milliseconds", "us": "microseconds", "ns": "nanoseconds"}
#: Unix times (s) counted as absolute: 1990-01-01 .. 2100-01-01
EPOCH_RANGE_S = (631_152_000, 4_102_444_800)


class Timestamps:
    """Timestamps of a source resolved to seconds since the first: ``seconds`` (float64 array,
    NaN where a value was missing), ``start_ns`` (Unix nanoseconds of the first, or None when the
    source counts from its own start), ``unit`` (s/ms/us/ns, or iso8601), ``epoch`` and ``note``
    (what was decided and why, for the ``source`` block)."""

    def __init__(self, seconds: np.ndarray, start_ns: int | None, unit: str, epoch: bool, note: str):
        self.seconds, self.start_ns, self.unit, self.epoch, self.note = seconds, start_ns, unit, epoch, note

    @property
    def start_time(self) -> str | None:
        return None if self.start_ns is None else utc_iso_from_ns(self.start_ns)

    def resolved(self) -> dict[str, str]:
        """The choice as option values for the ``source`` block (re-running with them repeats it)."""
        return {"timestamp_unit": self.unit, "timestamps": self.note}


def utc_iso_from_ns(t_ns: int) -> str:
    """ISO 8601 UTC text (nanosecond precision) of nanoseconds since the Unix epoch."""
    sec, ns = divmod(int(t_ns), 1_000_000_000)
    base = datetime.fromtimestamp(sec, tz=timezone.utc).strftime("%Y-%m-%dT%H:%M:%S")
    return f"{base}.{ns:09d}Z"


def iso_to_ns(text: str) -> int | None:
    """Unix nanoseconds of an ISO 8601 date-time (``Z``, an offset or none = UTC; any number of
    fraction digits), or None when the text is not one."""
    m = re.fullmatch(r"\s*(\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(?::\d{2})?)(?:[.,](\d{1,9})\d*)?"
                     r"(Z|[+-]\d{2}(?::?\d{2})?)?\s*", text)
    if not m:
        return None
    tz = m[3] or "Z"
    tz = "+00:00" if tz == "Z" else (tz + ":00" if len(tz) == 3 else tz if ":" in tz else tz[:3] + ":" + tz[3:])
    try:
        dt = datetime.fromisoformat(m[1].replace(" ", "T") + tz).astimezone(timezone.utc)
    except ValueError:
        return None
    return int(dt.timestamp()) * 1_000_000_000 + int((m[2] or "").ljust(9, "0"))


def to_utc(ts: str) -> str:
    """Any ISO 8601 timestamp (with offset) -> UTC ``...Z`` keeping the fraction digits."""
    s = ts.strip()
    m = re.match(r"^(\d{4}-\d{2}-\d{2})[T ](\d{2}:\d{2}:\d{2})(?:\.(\d{1,9}))?(Z|[+-]\d{2}(?::?\d{2})?)?$", s)
    if not m:
        raise FormatError(f"{ts!r} is not an ISO 8601 timestamp")
    date, hms, frac, tz = m.groups()
    tz = tz or "Z"
    if tz in ("Z", "+00", "+0000", "+00:00", "-00:00"):
        return f"{date}T{hms}{'.' + frac if frac else ''}Z"
    if len(tz) == 3:
        tz += ":00"
    elif ":" not in tz:
        tz = tz[:3] + ":" + tz[3:]
    dt = datetime.fromisoformat(f"{date}T{hms}{tz}").astimezone(timezone.utc)
    return dt.strftime("%Y-%m-%dT%H:%M:%S") + (f".{frac}" if frac else "") + "Z"


def timestamp_value(v: Any) -> int | float | Decimal | str | None:
    """A number kept exact where it is written exactly: an integer (text) as an int, a decimal
    text (``"1631441453.299504000"``) or a ``Decimal`` (a JSON parser's exact number) as a
    ``Decimal``, so that epoch seconds keep their nanoseconds (a float64 of an epoch in seconds
    has a step of 238 ns); a float as it is; an ISO text kept as text; None where absent or
    unreadable."""
    if v is None or isinstance(v, bool):
        return None
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, Decimal):
        return v if v.is_finite() else None
    if isinstance(v, str):
        t = v.strip()
        if t.lstrip("+-").isdigit():
            return int(t)
        try:
            d = Decimal(t)
        except InvalidOperation:
            return t if iso_to_ns(t) is not None else None
        return d if d.is_finite() else None
    return None


def _exact(v: int | float | Decimal) -> int | Decimal:
    """An int as it is, a float or Decimal as the exact Decimal of its value."""
    return v if isinstance(v, (int, Decimal)) else Decimal(v)


def resolve_timestamps(values: Sequence[Any], unit: str = "auto", *, what: str = "timestamps"
                       ) -> Timestamps:
    """Seconds since the first of timestamps whose unit and epoch a format leaves open (OpenLABEL's
    ``frame_properties.timestamp``: numbers or numeric strings, or ISO 8601 texts).

    ``unit`` = ``auto`` infers it: values whose magnitude puts them between 1990 and 2100 as
    seconds, milliseconds, microseconds or nanoseconds since the Unix epoch are read so (the four
    ranges are 1000x apart, so at most one fits); smaller values count from the source's own
    start, in the unit their median spacing suggests (< 5: s, < 5e3: ms, < 5e6: us, else ns — a
    frame period of 0.2 ms .. 5 s). A given ``unit`` fixes the unit; the epoch is still told by
    the magnitude. ISO texts are absolute. Values are kept exact (integers) until the difference
    to the first is taken, so nanosecond epochs lose nothing."""
    if unit not in TIMESTAMP_UNITS:
        raise FormatError(f"timestamp_unit {unit!r}: expected one of {', '.join(TIMESTAMP_UNITS)}")
    vals = [timestamp_value(v) for v in values]
    have = [v for v in vals if v is not None]
    n = len(vals)
    if not have:
        return Timestamps(np.full(n, np.nan), None, unit if unit != "auto" else "s", False,
                          f"no {what}")
    if any(isinstance(v, str) for v in have):
        if not all(isinstance(v, str) for v in have):
            raise FormatError(f"{what} mix ISO 8601 texts and numbers")
        ns = [None if v is None else iso_to_ns(v) for v in vals]
        t0 = min(x for x in ns if x is not None)
        sec = np.array([np.nan if x is None else (x - t0) / 1e9 for x in ns])
        return Timestamps(sec, t0, "iso8601", True, f"{what}: ISO 8601 date-times (UTC)")
    mag = max(abs(float(v)) for v in have)
    srt = np.unique(np.asarray([float(v) for v in have]))
    dts = np.diff(srt)
    spacing = float(np.median(dts)) if len(dts) else None
    how = "given"
    epoch = False
    if unit == "auto":
        how = "inferred from magnitude %.3g" % mag + (f" and spacing {spacing:.3g}" if spacing else "")
        for u in ("s", "ms", "us", "ns"):
            if EPOCH_RANGE_S[0] <= mag * _NS_PER[u] / 1e9 <= EPOCH_RANGE_S[1]:
                unit, epoch = u, True
                break
        else:
            sp = spacing if spacing else 0.0
            unit = "s" if sp < 5 else "ms" if sp < 5e3 else "us" if sp < 5e6 else "ns"
    else:
        epoch = EPOCH_RANGE_S[0] <= mag * _NS_PER[unit] / 1e9 <= EPOCH_RANGE_S[1]
    scale = _NS_PER[unit]
    first = min(have)
    if all(isinstance(v, int) for v in have):
        sec = np.array([np.nan if v is None else (v - first) * scale / 1e9 for v in vals])
        start_ns = first * scale if epoch else None
    else:  # exact decimal arithmetic down to the nanosecond (no float of the epoch value)
        d0 = _exact(first)
        sec = np.array([np.nan if v is None else float((_exact(v) - d0) * scale) / 1e9 for v in vals])
        start_ns = int((d0 * scale).to_integral_value(ROUND_HALF_EVEN)) if epoch else None
    ref = "since the Unix epoch" if epoch else "since the start of the recording"
    return Timestamps(sec, start_ns, unit, epoch, f"{what}: {_UNIT_WORD[unit]} {ref} ({how})")
