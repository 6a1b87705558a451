"""The dataset report as a self-contained HTML page (standard library only). In a reports
directory, the worst recordings link to their own HTML reports (files next to the page)."""

from __future__ import annotations

import html
from typing import Any


def render_dataset_html(d: dict[str, Any]) -> str:
    """A self-contained HTML page of a dataset report (``DatasetReport.to_dict()``)."""
    e = html.escape

    def table(head: list[str], rows: list[list[Any]]) -> str:
        if not rows:
            return "<p><em>none</em></p>"
        h = "".join(f"<th>{e(str(x))}</th>" for x in head)
        body = "".join("<tr>" + "".join(f"<td>{_cell(v)}</td>" for v in r) + "</tr>"
                       for r in rows)
        return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"

    c = d["counts"]
    status = {0: "passed", 1: "findings", 3: "failures"}.get(d["exit_code"], str(d["exit_code"]))
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>aveas-format {e(d['kind'])} report: {d['recordings']} recordings</title>",
        "<style>body{font-family:system-ui,sans-serif;margin:2em;max-width:80em}"
        "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;"
        "padding:.25em .6em;text-align:left;font-size:.9em}th{background:#f3f3f3}"
        ".s{font-size:1.1em}.passed{color:#1a7f37}.findings{color:#9a6700}"
        ".failures{color:#cf222e}</style></head><body>",
        f"<h1>Dataset {e(d['kind'])} report</h1>",
        f"<p class='s'>{d['recordings']} recordings: {d.get('valid', 0)} valid, "
        f"{d['failed']} failed to process; {c.get('error', 0)} errors, "
        f"{c.get('warning', 0)} warnings, {c.get('info', 0)} infos. Status: "
        f"<b class='{status}'>{status}</b> (exit code {d['exit_code']}, fail-on "
        f"{e(str(d['fail_on']))}), {d['seconds']} s, tool {e(d['tool_version'])}.</p>",
        f"<p>Dataset: {e(', '.join(map(str, d['dataset']))[:2000])}</p>",
        "<h2>Findings by rule</h2>",
        table(["rule", "severity", "title", "findings", "recordings"],
              [[k, v["severity"], v["title"], v["count"], v["recordings"]]
               for k, v in d["by_rule"].items()]),
        "<h2>By partner</h2>",
        table(["partner", "recordings", "valid", "failed", "errors", "warnings", "infos",
               "top rules"],
              [[k, v["recordings"], v["valid"], v["failed"], v["error"], v["warning"], v["info"],
                ", ".join(f"{r} ({n})" for r, n in sorted(v["rules"].items(),
                                                           key=lambda kv: -kv[1])[:5])]
               for k, v in d["by_partner"].items()]),
        "<h2>Worst recordings</h2>",
        table(["recording", "id", "partner", "status", "errors", "warnings", "infos", "rules",
               "error"],
              [[_link(w["path"], w.get("report_html")), w.get("recording_id"), w.get("partner"), w["status"],
                *((w["counts"] or {}).get(k) for k in ("error", "warning", "info")),
                ", ".join(w.get("top_rules") or []), w.get("error")] for w in d["worst"]]),
        *([] if d["kind"] == "validate" else [
            "<h2>Recordings</h2>",
            table(["recording", "id", "partner", "output", "derived", "events", "min TTC (s)",
                   "min PET (s)", "near misses", "hard braking", "seconds"],
                  [[x["path"], x.get("recording_id"), x.get("partner"), x.get("output"),
                    ", ".join(x.get("derived") or []), x.get("events"), _fmt(x.get("min_ttc_s")),
                    _fmt(x.get("min_pet_s")), x.get("near_misses"), x.get("hard_braking"),
                    x.get("seconds")] for x in d["entries"]])]),
        "<h2>Recordings that failed</h2>",
        table(["recording", "error"], [[f["path"], f["error"]] for f in d["failures"]]),
        "</body></html>\n",
    ]
    return "".join(parts)


class _Html(str):
    """A table cell that is HTML already (escaped where it holds text)."""


def _link(text: str, href: str | None) -> str:
    """``text`` linked to ``href`` (a file next to the page), or plain text without one."""
    if not href:
        return text
    return _Html(f"<a href='{html.escape(href)}'>{html.escape(text)}</a>")


def _cell(v: Any) -> str:
    return v if isinstance(v, _Html) else html.escape("" if v is None else str(v))


def _fmt(v: Any) -> str:
    return "" if v is None else f"{v:.3g}"
