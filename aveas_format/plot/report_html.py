"""The HTML validation report: one self-contained file (inline CSS, figures as base64 PNG, no scripts,
no CDN), readable when sent by e-mail. It lives in the presentation layer with the figures it
embeds; ``aveas_format.validate`` renders text and JSON only.

Layout (after gtfs-validator's report): the verdict; a **summary** of the recording (participants
per class, duration, rates, map, CRS, coverage, provenance, acquisition, rights) beside the counts
per severity; the extra sections a caller passes (``sections``: the place of a criticality
summary); the **rules with findings** (each code's doc as a tooltip, a link to its section below
and, with ``docs_url``, to its entry in docs/rules.md); tool failures; the **figures**; then one
expandable section per rule with its doc (reStructuredText rendered), the docs/format.md sentence it
enforces, its count and its sampled findings.
"""

from __future__ import annotations

import base64
import html
from collections.abc import Sequence
from typing import Any

from aveas_format.plot.recording import figures as recording_figures
from aveas_format.plot.recording import png_bytes, recording_name
from aveas_format.validate.registry import load_rules
from aveas_format.validate.render import inline_markup, message_text, rule_anchor
from aveas_format.validate.report import Report, Severity

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:1.5rem auto;max-width:1200px;
color:#222;padding:0 1rem;line-height:1.4}
h1{font-size:1.5rem;margin-bottom:.2rem} h2{border-bottom:1px solid #ddd;padding-bottom:.2rem;margin-top:2rem}
h3{margin:.2rem 0} .muted{color:#666;font-size:.9rem}
.badge{display:inline-block;padding:.1rem .5rem;border-radius:.6rem;font-size:.8rem;font-weight:600;
color:#fff;vertical-align:middle}
.error{background:#c62828}.warning{background:#ef6c00}.info{background:#1565c0}.failure{background:#6a1b9a}
.valid{background:#2e7d32}
table{border-collapse:collapse;width:100%;font-size:.85rem;margin:.4rem 0 1rem}
th,td{border:1px solid #e0e0e0;padding:.25rem .45rem;text-align:left;vertical-align:top}
th{background:#f5f5f5} td.num{text-align:right;font-variant-numeric:tabular-nums}
.summary{display:grid;grid-template-columns:minmax(0,2fr) minmax(0,1fr);gap:1.2rem;align-items:start}
.card{border:1px solid #e0e0e0;border-radius:.4rem;padding:.6rem .9rem}
.card h3{font-size:1rem;margin-bottom:.4rem} .facts th{width:11rem;background:none;font-weight:600}
.facts td,.facts th{border:none;border-bottom:1px solid #eee;padding:.2rem .3rem}
.counts{display:grid;grid-template-columns:repeat(3,1fr);gap:.5rem;margin:.3rem 0 .6rem}
.count{border-radius:.4rem;color:#fff;text-align:center;padding:.4rem 0}
.count b{display:block;font-size:1.6rem;line-height:1.2}
.count.zero{background:#e8e8e8;color:#555}
details.rule{border-left:4px solid #ccc;padding:.2rem .8rem;margin:.8rem 0;background:none}
details.rule.error{border-color:#c62828}details.rule.warning{border-color:#ef6c00}
details.rule.info{border-color:#1565c0}
details.rule>summary{cursor:pointer;list-style-position:outside}
figure{margin:1rem 0} figure img{max-width:100%;border:1px solid #eee} figcaption{color:#555;font-size:.85rem}
.grid{display:grid;grid-template-columns:1fr 1fr;gap:1rem} pre{background:#f7f7f7;padding:.5rem;overflow:auto;
font-size:.75rem} code{font-size:.85rem;background:#f3f3f3;padding:0 .2rem;border-radius:.2rem}
a.doc{font-size:.8rem;margin-left:.4rem} abbr{text-decoration:none;cursor:help}
"""

_LOC = ("file", "table", "row", "participant_id", "time", "column", "x", "y", "road_id", "lane_id",
        "line", "frame", "uid", "json_path", "message_index", "object_id", "entity")


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


def _v(x: Any) -> str:
    """An enum's value, anything else as text."""
    return str(getattr(x, "value", x))


def _num(v: float | None, unit: str = "", digits: int = 4) -> str | None:
    return None if v is None else f"{v:.{digits}g}{' ' + unit if unit else ''}"


def recording_facts(rec: Any) -> list[tuple[str, str]]:
    """(label, text) of what the report says about the recording: who and what is in it, how long
    and how often it was sampled, the map, CRS, coverage, provenance, acquisition and rights.
    Missing facts are left out."""
    import numpy as np

    m = rec.meta
    facts: list[tuple[str, str | None]] = [("Title", m.title), ("Recording id", m.recording_id)]
    if getattr(rec, "path", None):
        facts.append(("File", str(rec.path)))
    p = rec.participants
    if p is not None and p.num_rows and "class" in p.column_names:
        import pyarrow as pa
        import pyarrow.compute as pc

        counts = sorted(pc.value_counts(p.column("class").cast(pa.string())).to_pylist(),
                        key=lambda d: (-d["counts"], str(d["values"])))
        facts.append(("Participants", f"{p.num_rows:,}: " + ", ".join(
            f"{d['counts']:,} {d['values']}" for d in counts)))
    states = m.tables.get("states")
    if states is not None:
        facts.append(("State rows", f"{states.rows:,}"))
    rate = _num(m.nominal_rate_hz, "Hz")
    s = rec.states
    if s is not None and s.num_rows > 1 and {"participant_id", "time"} <= set(s.column_names):
        pid = np.asarray(s.column("participant_id").to_numpy(zero_copy_only=False), np.int64)
        t = np.asarray(s.column("time").to_numpy(zero_copy_only=False), np.float64)
        same = pid[1:] == pid[:-1]
        dt = (t[1:] - t[:-1])[same]
        dt = dt[np.isfinite(dt) & (dt > 0)]
        if len(dt):
            rate = f"{rate} nominal, {1.0 / float(np.median(dt)):.4g} Hz observed (median)"
    facts += [("Duration", _num(m.duration_s, "s")), ("Sample rate", rate),
              ("Start time", str(m.start_time) if m.start_time else None)]
    map_text = f"{m.map.file} (OpenDRIVE {m.map.opendrive_version})"
    try:
        net = rec.map
        map_text += f": {len(net.roads)} roads, {len(net.junctions)} junctions"
    except Exception:  # noqa: BLE001 — an unreadable map is a map.* finding; the fact stays short
        pass
    facts += [("Map", map_text), ("CRS", m.crs),
              ("Location", f"{m.location.lat:.6f}° N, {m.location.lon:.6f}° E")]
    if m.coverage:
        try:
            import shapely

            g = shapely.from_wkt(m.coverage)
            x0, y0, x1, y1 = g.bounds
            facts.append(("Coverage", f"{g.area / 1e6:.4g} km² ({g.area:,.0f} m²), x {x0:,.1f}..."
                                      f"{x1:,.1f} m, y {y0:,.1f}...{y1:,.1f} m"))
        except Exception:  # noqa: BLE001 — malformed WKT is a geo.* finding
            facts.append(("Coverage", m.coverage[:120]))
    else:
        facts.append(("Coverage", "not given"))
    a = m.acquisition
    acq = f"{_v(a.method)}, by {a.partner}" + (f"; {a.platform}" if a.platform else "")
    if a.sensors:
        acq += "; sensors: " + ", ".join(f"{x.id} ({_v(x.kind)})" for x in a.sensors)
    facts += [("Provenance", _v(m.provenance)), ("Acquisition", acq),
              ("Rights", f"{_v(m.rights.right_of_use)}, {m.rights.license}, {m.rights.owner}")]
    if m.source is not None:
        facts.append(("Converted by",
                      f"{m.source.converter} {m.source.converter_version or ''}".strip()))
    return [(k, v) for k, v in facts if v]


def _rule_link(code: str, docs_url: str | None) -> str:
    if not docs_url:
        return ""
    url = f"{docs_url.rstrip('/')}/rules.md#{rule_anchor(code)}"
    return f"<a class='doc' href='{_e(url)}' title='the rule in docs/rules.md'>docs ↗</a>"


def _summary(report: Report, rec: Any, rec_error: str | None) -> list[str]:
    c = report.counts
    out = ["<h2>Summary</h2><div class='summary'><div class='card'><h3>Recording</h3>"]
    if rec is not None:
        try:
            facts = recording_facts(rec)
        except Exception as e:  # noqa: BLE001 — the facts are a bonus; the findings are the report
            facts, rec_error = [], f"{type(e).__name__}: {e}"
        if facts:
            out.append("<table class='facts'>" + "".join(
                f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in facts) + "</table>")
        note = getattr(rec, "figure_note", None)
        if note:
            out.append(f"<p class='muted'>Rates and figures {_e(note)}.</p>")
    if rec is None or rec_error:
        out.append(f"<p class='muted'>The recording could not be read for a summary"
                   f"{': ' + _e(rec_error) if rec_error else ''}; the findings below say why.</p>")
    out.append("</div><div class='card'><h3>Findings</h3><div class='counts'>")
    for sev in Severity:
        n = c[sev.value]
        rules = sum(1 for r in report.results if r.severity is sev and r.count)
        out.append(f"<div class='count {sev.value if n else 'zero'}'><b>{n:,}</b>{sev.value}"
                   f"{'s' if n != 1 and sev is not Severity.INFO else ''}<br>"
                   f"<small>{rules} rule{'s' if rules != 1 else ''}</small></div>")
    out.append("</div>")
    ran = f"{len(report.rules_run)} rules ran in {report.seconds:.2f} s"
    if report.failures:
        ran += f"; <b>{len(report.failures)} crashed</b> (tool failures)"
    if report.streamed:
        ran += "; streamed: " + ", ".join(f"{_e(k)} ({v} batches)" for k, v in
                                          report.streamed.items())
    out.append(f"<p class='muted'>{ran}.</p>")
    out.append("<p class='muted'>Errors break a MUST of the format (exit code 1), warnings a "
               "SHOULD or a plausibility limit, info has no quality impact.</p></div></div>")
    return out


def render_html(report: Report, rec: Any = None, figures: dict[str, bytes] | None = None, *,
                docs_url: str | None = None, sections: Sequence[tuple[str, str]] = (),
                no_figures: str = "not requested") -> str:
    """The report as one HTML page. ``rec`` (a Recording) adds the summary of the recording and
    the figures; without it (or when it cannot be drawn) the page says so. ``docs_url``: the
    base URL of the docs (``https://.../docs``): each rule then links to its entry in
    ``rules.md`` there; without it the page stands alone (every rule's doc is in the page).
    ``sections``: ``(title, HTML body)`` inserted after the summary (e.g. a criticality summary).
    ``no_figures``: why there are none when ``figures`` is given empty."""
    reg = load_rules()
    fig_error = None
    if figures is None:
        try:
            figures = report_figures(report, rec)
        except Exception as e:  # noqa: BLE001 — figures are a bonus; the findings are the report
            figures = {}
            fig_error = str(e) if isinstance(e, ImportError) else f"{type(e).__name__}: {e}"
        else:
            fig_error = None if rec is not None else "the recording could not be read for figures"
    status = {"tool failure": ("failure", "TOOL FAILURE"), "invalid": ("error", "INVALID"),
              "valid": ("valid", "VALID")}[report.status]
    name = recording_name(rec) if rec is not None else str(report.recording)
    out = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>Validation report — {_e(name)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(name)} <span class='badge {status[0]}'>{status[1]}</span></h1>",
        f"<p class='muted'>Validation report of {_e(report.recording)} · format "
        f"{_e(report.format_version)} · aveas-format {_e(report.tool_version)}</p>",
    ]
    out += _summary(report, rec, None)
    # extra sections (the criticality summary goes here)
    for title, body in sections:
        out.append(f"<h2>{_e(title)}</h2>{body}")
    if report.results:
        out.append("<h2>Rules with findings</h2><table><tr><th>rule</th><th>severity</th>"
                   "<th>count</th><th>title</th></tr>")
        for r in report.results:
            rule = reg.get(r.code)
            tip = f" title='{_e(inline_markup(rule.doc))}'" if rule is not None else ""
            out.append(f"<tr><td><a href='#{_e(rule_anchor(r.code))}'{tip}><code>{_e(r.code)}"
                       f"</code></a>{_rule_link(r.code, docs_url)}</td>"
                       f"<td><span class='badge {r.severity.value}'>{r.severity.value}</span></td>"
                       f"<td class='num'>{r.count:,}</td><td>{_e(r.title)}</td></tr>")
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
            out.append(_img(figures["map"], "The map with the trajectories coloured by class, "
                                            "arrows in the direction of travel (a dot: standing "
                                            "still), the coverage and unobserved regions, and "
                                            "every finding with a position (one marker shape "
                                            "per rule, coloured by severity)"))
        out.append("<div class='grid'>")
        for key, cap in (("speed", "Speed per class"),
                         ("acceleration", "Longitudinal acceleration per class (negative: "
                                          "braking)")):
            if key in figures:
                out.append(_img(figures[key], cap))
        out.append("</div>")
        if "sample_rate" in figures:
            out.append(_img(figures["sample_rate"], "Sample rate over time"))
        note = getattr(rec, "figure_note", None) if rec is not None else None
        if note:
            out.append(f"<p class='muted'>Figures {_e(note)}; the findings cover every row.</p>")
    else:
        out.append(f"<p class='muted'>No figures: {_e(fig_error or no_figures)}.</p>")
    out.append("<h2>Findings by rule</h2>")
    if not report.results:
        out.append("<p>No findings.</p>")
    for r in report.results:
        rule = reg.get(r.code)
        shown = len(r.sample)
        opened = " open" if r.severity is Severity.ERROR else ""
        out.append(f"<details class='rule {r.severity.value}' id='{_e(rule_anchor(r.code))}'"
                   f"{opened}><summary><h3 style='display:inline'><code>{_e(r.code)}</code> — "
                   f"{_e(r.title)}</h3> <span class='badge {r.severity.value}'>"
                   f"{r.severity.value}</span> <b>{r.count:,}</b> finding"
                   f"{'s' if r.count != 1 else ''}{f', {shown} shown' if r.truncated else ''}"
                   f"{_rule_link(r.code, docs_url)}</summary>")
        if rule is not None:
            out.append(f"<p>{inline_markup(rule.doc, html=True)}</p>")
            if rule.enforces:
                out.append(f"<p class='muted'>Enforces: {inline_markup(rule.enforces, html=True)}"
                           "</p>")
        cols = [k for k in _LOC if any(getattr(f.location, k) is not None for f in r.sample)]
        out.append("<table><tr>" + "".join(f"<th>{k}</th>" for k in cols) + "<th>message</th></tr>")
        for f in r.sample:
            out.append("<tr>" + "".join(f"<td>{_e(getattr(f.location, k))}</td>" for k in cols) +
                       f"<td>{_e(message_text(f))}</td></tr>")
        out.append("</table></details>")
    out.append(f"<p class='muted'>aveas-format {_e(report.tool_version)}. Rule documentation: "
               + (f"<a href='{_e(docs_url.rstrip('/'))}/rules.md'>rules.md</a>" if docs_url
                  else "docs/rules.md of aveas-format (each rule's doc is in its section above)")
               + ".</p>")
    out.append("</body></html>")
    return "\n".join(out)
