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
from rich.text import Text

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


#: a message's own location prefix: ``states.parquet: row 2400: `` (or ``recording.json: ``)
_MESSAGE_PLACE = re.compile(r"^(?P<file>[\w./-]+\.(?:parquet|json|xodr)): (?:row (?P<row>\d+): )?")


def message_text(finding) -> str:
    """A finding's message without the location it starts with where its :class:`Location`
    already says it (``states.parquet: row 2400: participant 3 ...`` beside file states.parquet,
    row 2400 -> ``participant 3 ...``): a rendered finding names its place once."""
    m = _MESSAGE_PLACE.match(finding.message)
    if m is None:
        return finding.message
    loc = finding.location
    files = {loc.file, f"{loc.table}.parquet" if loc.table else None}
    same_row = m.group("row") is None or (loc.row is not None and int(m.group("row")) == loc.row)
    if m.group("file") in files and same_row:
        return finding.message[m.end():]
    return finding.message


def _plural(n: int, word: str) -> str:
    return f"{n} {word}" if n == 1 else f"{n} {word}s"


def verdict(report: Report, fail_on: str = "error") -> str:
    """The verdict as a user reads it, true also at another ``--fail-on``: ``VALID``,
    ``INVALID``, ``VALID with 1 warning, failing at --fail-on warning (exit 1)``, ``INVALID, not
    failing at --fail-on never (exit 0)``, ``FAILED (tool failure)``."""
    c = report.counts
    if report.failures:
        return "FAILED (tool failure)"
    status = "INVALID" if c["error"] else "VALID"
    code, default = report.exit_code(fail_on), report.exit_code("error")
    if code == default:
        return status
    if code:
        kept = [_plural(c[k], k) for k in ("warning", "info") if c[k] and Severity(k).rank >= Severity(fail_on).rank]
        return f"{status} with {' and '.join(kept)}, failing at --fail-on {fail_on} (exit {code})"
    return f"{status}, not failing at --fail-on {fail_on} (exit {code})"


def render_text(report: Report, *, color: bool = False, width: int = 120, fail_on: str = "error") -> str:
    """One greppable line per sampled finding (``SEVERITY code location: message``, the place
    named once), a line per truncated rule, then a summary table by rule and the totals with the
    verdict at ``fail_on`` (:func:`verdict`)."""
    buf = io.StringIO()
    con = Console(file=buf, force_terminal=color, no_color=not color, width=width, highlight=False,
                  soft_wrap=True)
    for r in report.results:
        for f in r.sample:
            loc = f.location.text()
            con.print(Text.assemble((f"{f.severity.value.upper():7}", _STYLE[f.severity]),
                                    f" {f.code} {loc + ': ' if loc else ''}{message_text(f)}"))
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
    con.print(f"{report.recording}: {verdict(report, fail_on)} — {c['error']} errors, {c['warning']} "
              f"warnings, {c['info']} info ({len(report.rules_run)} rules, {report.seconds:.2f} s)",
              markup=False)
    return buf.getvalue()
