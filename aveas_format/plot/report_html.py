"""The HTML validation report: one self-contained file (inline CSS, figures as base64 PNG, no scripts,
no CDN). It lives in the presentation layer with the figures it embeds; ``aveas_format.validate``
renders text and JSON only.

Sections: a summary by severity, tool failures, the figures (map with lanes, trajectories and the
located findings; speed and acceleration per class; sample rate over time), then one section per
rule with its doc, the FORMAT.md sentence it enforces, its count and its sampled findings.
"""

from __future__ import annotations

import base64
import html
from typing import Any

from aveas_format.plot.recording import figures as recording_figures
from aveas_format.plot.recording import png_bytes
from aveas_format.validate.registry import load_rules
from aveas_format.validate.report import Report, Severity

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:2rem auto;max-width:1200px;
color:#222;padding:0 1rem}
h1{font-size:1.5rem;margin-bottom:.2rem} h2{border-bottom:1px solid #ddd;padding-bottom:.2rem;margin-top:2rem}
h3{margin-bottom:.3rem} .muted{color:#666;font-size:.9rem}
.badge{display:inline-block;padding:.1rem .5rem;border-radius:.6rem;font-size:.8rem;font-weight:600;
color:#fff}
.error{background:#c62828}.warning{background:#ef6c00}.info{background:#1565c0}.failure{background:#6a1b9a}
.valid{background:#2e7d32}
table{border-collapse:collapse;width:100%;font-size:.85rem;margin:.4rem 0 1rem}
th,td{border:1px solid #e0e0e0;padding:.25rem .45rem;text-align:left;vertical-align:top}
th{background:#f5f5f5} td.num{text-align:right;font-variant-numeric:tabular-nums}
.summary td{font-size:1rem} .rule{border-left:4px solid #ccc;padding-left:.8rem;margin:1.2rem 0}
.rule.error{background:none;border-color:#c62828}.rule.warning{background:none;border-color:#ef6c00}
.rule.info{background:none;border-color:#1565c0}
figure{margin:1rem 0} figure img{max-width:100%;border:1px solid #eee} figcaption{color:#555;font-size:.85rem}
.grid{display:grid;grid-template-columns:1fr 1fr;gap:1rem} pre{background:#f7f7f7;padding:.5rem;overflow:auto;
font-size:.75rem} code{font-size:.85rem}
"""

_LOC = ("file", "table", "row", "participant_id", "time", "column", "x", "y", "road_id", "lane_id",
        "line")


def _e(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return html.escape(f"{v:.6g}")
    return html.escape(str(v))


def _img(png: bytes, caption: str) -> str:
    b64 = base64.b64encode(png).decode("ascii")
    return (f'<figure><img alt="{_e(caption)}" src="data:image/png;base64,{b64}">'
            f"<figcaption>{_e(caption)}</figcaption></figure>")


def report_figures(report: Report, rec: Any) -> dict[str, bytes]:
    """PNG bytes of the report figures (empty when the recording cannot be drawn)."""
    if rec is None:
        return {}
    return {name: png_bytes(fig) for name, fig in recording_figures(rec, report.findings()).items()}


def render_html(report: Report, rec: Any = None, figures: dict[str, bytes] | None = None) -> str:
    """The report as one HTML page. ``rec`` (a Recording) adds the figures; without it (or when it
    cannot be drawn) the page says so."""
    reg = load_rules()
    c = report.counts
    if figures is None:
        try:
            figures = report_figures(report, rec)
        except Exception as e:  # noqa: BLE001 — figures are a bonus; the findings are the report
            figures = {}
            fig_error = f"{type(e).__name__}: {e}"
        else:
            fig_error = None if rec is not None else "the recording could not be read for figures"
    else:
        fig_error = None
    status = ("failure", "TOOL FAILURE") if report.failures else (
        ("error", "INVALID") if c["error"] else ("valid", "VALID"))
    out = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        f"<title>Validation report — {_e(report.recording)}</title><style>{_CSS}</style></head><body>",
        f"<h1>Validation report <span class='badge {status[0]}'>{status[1]}</span></h1>",
        f"<p class='muted'>{_e(report.recording)} · format {_e(report.format_version)} · "
        f"aveas-format {_e(report.tool_version)} · {len(report.rules_run)} rules in "
        f"{report.seconds:.2f} s</p>",
        "<h2>Summary</h2><table class='summary'><tr><th>severity</th><th>findings</th>"
        "<th>rules</th></tr>",
    ]
    for sev in Severity:
        n_rules = sum(1 for r in report.results if r.severity is sev and r.count)
        out.append(f"<tr><td><span class='badge {sev.value}'>{sev.value}</span></td>"
                   f"<td class='num'>{c[sev.value]}</td><td class='num'>{n_rules}</td></tr>")
    out.append("</table>")
    if report.results:
        out.append("<table><tr><th>rule</th><th>severity</th><th>count</th><th>title</th></tr>")
        for r in report.results:
            out.append(f"<tr><td><a href='#{_e(r.code)}'><code>{_e(r.code)}</code></a></td>"
                       f"<td><span class='badge {r.severity.value}'>{r.severity.value}</span></td>"
                       f"<td class='num'>{r.count}</td><td>{_e(r.title)}</td></tr>")
        out.append("</table>")
    from aveas_format.plot.criticality import criticality_section

    out.append(criticality_section(rec))
    if report.failures:
        out.append("<h2>Tool failures</h2><p>These rules crashed: a bug of the tool, not a finding "
                   "about the data (exit code 3).</p>")
        for f in report.failures:
            out.append(f"<h3><code>{_e(f.code)}</code></h3><p>{_e(f.error)}</p>"
                       f"<pre>{_e(f.traceback)}</pre>")
    out.append("<h2>Figures</h2>")
    if figures:
        if "map" in figures:
            out.append(_img(figures["map"], "Map lanes, trajectories and the findings located on "
                                            "them (x: error, ▲: warning, ●: info)"))
        out.append("<div class='grid'>")
        for name, cap in (("speed", "Speed per class"), ("acceleration", "Acceleration per class")):
            if name in figures:
                out.append(_img(figures[name], cap))
        out.append("</div>")
        if "sample_rate" in figures:
            out.append(_img(figures["sample_rate"], "Sample rate over time"))
        note = getattr(rec, "figure_note", None) if rec is not None else None
        if note:
            out.append(f"<p class='muted'>Figures {_e(note)}; the findings cover every row.</p>")
    else:
        out.append(f"<p class='muted'>No figures: {_e(fig_error or 'not requested')}.</p>")
    out.append("<h2>Findings by rule</h2>")
    if not report.results:
        out.append("<p>No findings.</p>")
    for r in report.results:
        rule = reg.get(r.code)
        out.append(f"<div class='rule {r.severity.value}' id='{_e(r.code)}'>"
                   f"<h3><code>{_e(r.code)}</code> — {_e(r.title)} "
                   f"<span class='badge {r.severity.value}'>{r.severity.value}</span></h3>")
        if rule is not None:
            out.append(f"<p>{_e(rule.doc)}</p>")
            if rule.enforces:
                out.append(f"<p class='muted'>Enforces: {_e(rule.enforces)}</p>")
        shown = len(r.sample)
        out.append(f"<p><b>{r.count}</b> finding{'s' if r.count != 1 else ''}"
                   f"{f', {shown} shown' if r.truncated else ''}.</p>")
        cols = [k for k in _LOC if any(getattr(f.location, k) is not None for f in r.sample)]
        out.append("<table><tr>" + "".join(f"<th>{k}</th>" for k in cols) + "<th>message</th></tr>")
        for f in r.sample:
            out.append("<tr>" + "".join(f"<td>{_e(getattr(f.location, k))}</td>" for k in cols) +
                       f"<td>{_e(f.message)}</td></tr>")
        out.append("</table></div>")
    out.append("</body></html>")
    return "\n".join(out)
