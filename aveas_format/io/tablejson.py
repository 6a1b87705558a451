"""A table of a recording as JSON and back, losslessly: :func:`table_to_json` /
:func:`table_from_json`, and :func:`json_safe` for the values.

JSON has no NaN, infinity or bytes: non-finite floats are listed by row, binary values written as
``{"base64": ...}``, and a derived table's ``aveas_derived`` schema metadata (how it was made) is
kept; the way back conforms the columns to the table's declared types. The OpenLABEL export
carries the tables the profile cannot (``unobserved``, ``events``, ..., the derived tables) in its
``aveas_format`` extension this way, and its import restores them.
"""

from __future__ import annotations

import base64
import json
import math
from typing import Any

import numpy as np
import pyarrow as pa

from aveas_format.io.arrow import conform
from aveas_format.schema.tables import TABLES


def json_safe(v: Any) -> Any:
    """JSON-safe: NaN -> None, numpy scalars -> Python."""
    if isinstance(v, (np.floating, float)):
        v = float(v)
        return None if math.isnan(v) or math.isinf(v) else v
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, (bytes, bytearray)):
        return {"base64": base64.b64encode(bytes(v)).decode()}
    if isinstance(v, dict):
        return {k: json_safe(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_safe(x) for x in v]
    return v


#: schema-metadata key of a derived table (as ``aveas_format.derive.registry.DERIVED_KEY``)
_DERIVED_KEY = b"aveas_derived"
_NONFINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def table_to_json(table: pa.Table | None) -> dict[str, Any] | None:
    """A table as ``{"columns": {name: [values]}, "rows": n}`` (binary as base64, dictionary as
    plain). JSON has no NaN or infinity: the row indices of such float values go to
    ``"nonfinite": {name: {"NaN"|"Infinity"|"-Infinity": [rows]}}`` (the list holds null there), and
    the table's ``aveas_derived`` schema metadata (how a derived table was made) to
    ``"derived_info"``."""
    if table is None:
        return None
    cols = {}
    nonfinite: dict[str, dict[str, list[int]]] = {}
    for name in table.column_names:
        col = table.column(name)
        if pa.types.is_dictionary(col.type):
            col = col.cast(col.type.value_type)
        if pa.types.is_floating(col.type) and table.num_rows:
            x = col.to_numpy(zero_copy_only=False).astype(np.float64)
            valid = ~np.asarray(col.is_null().to_numpy(zero_copy_only=False), bool)
            bad = {key: np.flatnonzero(valid & m).tolist()
                   for key, m in (("NaN", np.isnan(x)), ("Infinity", np.isposinf(x)),
                                  ("-Infinity", np.isneginf(x)))}
            bad = {k: v for k, v in bad.items() if v}
            if bad:
                nonfinite[name] = bad
        cols[name] = json_safe(col.to_pylist())
    out: dict[str, Any] = {"columns": cols, "rows": table.num_rows}
    if nonfinite:
        out["nonfinite"] = nonfinite
    info = (table.schema.metadata or {}).get(_DERIVED_KEY)
    if info is not None:
        out["derived_info"] = info.decode("utf-8", "replace")
    return out


def table_from_json(obj: dict[str, Any] | None, name: str) -> pa.Table | None:
    """Inverse of :func:`table_to_json`, conformed to the format's declared types."""
    if not obj:
        return None
    spec = TABLES[name]
    nonfinite = obj.get("nonfinite") or {}
    arrays = {}
    for cname, vals in (obj.get("columns") or {}).items():
        fix = nonfinite.get(cname)
        if fix:
            vals = list(vals)
            for key, rows in fix.items():
                for i in rows:
                    if 0 <= int(i) < len(vals):
                        vals[int(i)] = _NONFINITE.get(key, math.nan)
        if any(isinstance(v, dict) and set(v) == {"base64"} for v in vals if v is not None):
            arrays[cname] = pa.array([None if v is None else base64.b64decode(v["base64"])
                                      for v in vals], pa.binary())
        else:
            try:
                arrays[cname] = pa.array(vals)
            except (pa.ArrowInvalid, pa.ArrowTypeError):
                arrays[cname] = pa.array([None if v is None else json.dumps(v) for v in vals])
    if not arrays:
        return None
    n = int(obj.get("rows", len(next(iter(arrays.values())))))
    arrays = {k: (v if len(v) == n else pa.nulls(n)) for k, v in arrays.items()}
    table = conform(pa.table(arrays), spec)
    info = obj.get("derived_info")
    if isinstance(info, str):
        md = dict(table.schema.metadata or {})
        md[_DERIVED_KEY] = info.encode()
        table = table.replace_schema_metadata(md)
    return table
