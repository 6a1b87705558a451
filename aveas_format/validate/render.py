"""Renderers of a validation report: text (greppable lines + a summary table) and JSON."""

from __future__ import annotations

import io

from rich.console import Console
from rich.table import Table

from aveas_format.validate.report import Report, Severity

_STYLE = {Severity.ERROR: "bold red", Severity.WARNING: "yellow", Severity.INFO: "cyan"}


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
