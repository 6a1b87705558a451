"""The criticality section of the HTML report: the recording's ``derived/criticality_summary``
(its own row and the participants with the smallest TTC) and the TTC/DRAC time series, with their
1-sigma bands, of the most critical pair.

:func:`criticality_section` returns an HTML fragment (empty where the recording has no summary);
``report_html.render_html`` places it after the summary.
"""

from __future__ import annotations

import base64
import html
from typing import Any

#: the summary's measures shown, with their std column and unit
ROWS = (("min TTC", "min_ttc", "min_ttc_std", "s"), ("TET", "tet", "tet_std", "s"),
        ("TIT", "tit", "tit_std", "s²"), ("max DRAC", "max_drac", "max_drac_std", "m/s²"),
        ("min PSD", "min_psd", "min_psd_std", ""), ("min PET", "min_pet", "min_pet_std", "s"),
        ("CPI", "cpi", "cpi_std", ""))


def _pm(v: Any, sd: Any) -> str:
    if v is None:
        return "–"
    return f"{v:.3g}" + (f" ± {sd:.2g}" if sd is not None else "")


def _read(rec: Any, name: str, *, participant_id: int | None = None,
          columns: list[str] | None = None):
    """Table ``name`` of the written recording ``rec`` (only the row groups of one participant,
    where given), or None when it has none or cannot be read."""
    import pyarrow.parquet as pq

    from aveas_format.io.container import Container

    path = getattr(rec, "path", None)
    entry = rec.meta.tables.get(name) if hasattr(rec, "meta") else None
    if path is None or entry is None:
        return None
    try:
        with Container(path) as c:
            filters = [("participant_id", "=", participant_id)] if participant_id is not None \
                else None
            return pq.read_table(c.input_file(f"{name}.parquet"), columns=columns,
                                 filters=filters)
    except Exception:  # noqa: BLE001 — the section is a bonus of the report
        return None


def _head(r: dict) -> str:
    return "recording" if r["participant_id"] is None else f"participant {r['participant_id']}"


def criticality_section(rec: Any, *, participants: int = 5, figure: bool = True) -> str:
    """HTML: a table of the recording row and the ``participants`` most critical participants of
    ``derived/criticality_summary``, and the TTC/DRAC figure of the pair with the smallest TTC."""
    if rec is None:
        return ""
    cs = rec.derived.get("criticality_summary")
    if cs is None:
        cs = _read(rec, "derived/criticality_summary")
    if cs is None or not cs.num_rows:
        return ""
    rows = cs.to_pylist()
    whole = next((r for r in rows if str(r["scope"]) == "recording"), None)
    per = sorted((r for r in rows if str(r["scope"]) == "participant" and r["min_ttc"] is not None),
                 key=lambda r: r["min_ttc"])[:participants]
    cols = ([whole] if whole else []) + per
    e = html.escape
    out = ["<h2>Criticality</h2>",
           "<p class='muted'>derived/criticality_summary: the recording and the participants "
           "with the smallest TTC; values ± 1 std (docs/derive.md).</p>",
           "<table><tr><th>measure</th>" + "".join(f"<th>{e(_head(r))}</th>" for r in cols)
           + "</tr>"]
    for label, k, sd, unit in ROWS:
        out.append(f"<tr><td>{e(label)}{f' ({e(unit)})' if unit else ''}</td>" + "".join(
            f"<td class='num'>{e(_pm(r[k], r[sd]))}</td>" for r in cols) + "</tr>")
    for label, k in (("samples below the TTC threshold", "ttc_samples_below"),
                     ("near misses", "near_misses"), ("hard braking", "hard_braking")):
        out.append(f"<tr><td>{e(label)}</td>" + "".join(
            f"<td class='num'>{r[k]}</td>" for r in cols) + "</tr>")
    out.append("<tr><td>worst events</td>" + "".join(
        f"<td>{e(', '.join(map(str, r['worst_events'] or [])) or '–')}</td>" for r in cols)
        + "</tr></table>")
    it = None
    if figure and per and per[0]["min_ttc_other_id"] is not None:
        it = rec.derived.get("interactions")
        if it is None:
            it = _read(rec, "derived/interactions", participant_id=per[0]["participant_id"],
                       columns=["participant_id", "time", "other_id", "relation", "ttc",
                                "ttc_std", "ttc_kind", "drac", "drac_std"])
    if it is not None and "drac" in it.column_names:
        from aveas_format.plot.derive import ttc_drac_figure
        from aveas_format.plot.recording import png_bytes

        r = per[0]
        t = r["min_ttc_time"]
        fig = ttc_drac_figure(it, r["participant_id"], r["min_ttc_other_id"],
                              xlim=(t - 6.0, t + 3.0))
        b64 = base64.b64encode(png_bytes(fig)).decode("ascii")
        cap = (f"TTC and DRAC of participant {r['participant_id']} to {r['min_ttc_other_id']} "
               f"around its minimum TTC ({_pm(r['min_ttc'], r['min_ttc_std'])} s at {t:.2f} s)")
        out.append(f'<figure><img alt="{e(cap)}" src="data:image/png;base64,{b64}">'
                   f"<figcaption>{e(cap)}</figcaption></figure>")
    return "\n".join(out)


__all__ = ["criticality_section"]
