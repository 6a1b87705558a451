"""Renderers of a validation report: text (greppable lines + a summary table) and JSON, and the
helpers every renderer of rule docs shares: :func:`inline_markup` (the reStructuredText inline
markup of docstrings, rendered or removed) and :func:`rule_anchor` (a rule's anchor in
docs/rules.md). The HTML report is :mod:`aveas_format.plot.report_html` (it embeds figures)."""

from __future__ import annotations

import html as _html
import io
import re

from rich.console import Console
from rich.table import Table

from aveas_format.validate.report import Report, Severity

_STYLE = {Severity.ERROR: "bold red", Severity.WARNING: "yellow", Severity.INFO: "cyan"}


#: reStructuredText inline markup of docstrings: ``literal``, :role:`target`, `interpreted`,
#: **strong**, *emphasis* (in this order: a literal may hold asterisks)
_INLINE = re.compile(r"``(?P<lit>.+?)``|:[\w:.-]+:`~?\.?(?P<role>[^`]+?)`|`(?P<interp>[^`]+?)`"
                     r"|\*\*(?P<strong>[^*]+?)\*\*|(?<![\w*])\*(?P<em>[^*\s][^*]*?)\*(?![\w*])")
_HTML_TAG = {"lit": "code", "role": "code", "interp": "code", "strong": "b", "em": "i"}


def inline_markup(text: str, *, html: bool = False) -> str:
    """The inline reStructuredText of a docstring (``window_s``, :func:`f`, **b**, *i*) rendered
    as HTML (escaped, with ``<code>``, ``<b>``, ``<i>``) or, by default, removed (plain text for
    terminals and tooltips): ``"``window_s`` (0.5 s)"`` -> ``"window_s (0.5 s)"``."""
    out, pos = [], 0
    for m in _INLINE.finditer(text):
        kind = m.lastgroup
        inner = m.group(kind)
        if kind == "role":
            inner = inner.rsplit("<", 1)[-1].rstrip(">") if inner.endswith(">") else inner
        if html:
            out.append(_html.escape(text[pos:m.start()]))
            out.append(f"<{_HTML_TAG[kind]}>{_html.escape(inner)}</{_HTML_TAG[kind]}>")
        else:
            out.append(text[pos:m.start()] + inner)
        pos = m.end()
    tail = text[pos:]
    out.append(_html.escape(tail) if html else tail)
    return "".join(out)


def rule_anchor(code: str) -> str:
    """The anchor of a rule's section in docs/rules.md (``geo.crs_mismatch`` -> ``geocrs_mismatch``,
    as GitHub and most Markdown renderers make it from the heading)."""
    return re.sub(r"[^a-z0-9_-]", "", code.lower())


def render_json(report: Report) -> str:
    return report.to_json()


def render_text(report: Report, *, color: bool = False, width: int = 120) -> str:
    """One greppable line per sampled finding (``SEVERITY code location: message``), a line per
    truncated rule, then a summary table by rule and the totals."""
    buf = io.StringIO()
    con = Console(file=buf, force_terminal=color, no_color=not color, width=width, highlight=False,
                  soft_wrap=True)
    for r in report.results:
        for f in r.sample:
            loc = f.location.text()
            con.print(f"[{_STYLE[f.severity]}]{f.severity.value.upper():7}[/] {f.code} "
                      f"{loc + ': ' if loc else ''}{f.message}", markup=True)
        if r.truncated:
            con.print(f"        {r.code}: … {r.count - len(r.sample)} more (total {r.count})")
    for fail in report.failures:
        con.print(f"[bold magenta]FAILURE[/] {fail.code}: the rule crashed: {fail.error}")
    if report.results:
        t = Table(title=None, show_edge=False, pad_edge=False)
        t.add_column("rule")
        t.add_column("severity")
        t.add_column("count", justify="right")
        t.add_column("title")
        for r in report.results:
            t.add_row(r.code, r.severity.value, str(r.count), r.title)
        con.print(t)
    c = report.counts
    status = "FAILED (tool failure)" if report.failures else ("INVALID" if c["error"] else "VALID")
    con.print(f"{report.recording}: {status} — {c['error']} errors, {c['warning']} warnings, "
              f"{c['info']} info ({len(report.rules_run)} rules, {report.seconds:.2f} s)")
    return buf.getvalue()
