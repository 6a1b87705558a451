"""The criticality of a recording for people: the HTML report's *Criticality* section and the
figure of one critical event.

- :func:`criticality_section`: an HTML fragment (empty where the recording has neither
  ``derived/criticality_summary`` nor derived events): the summary of the recording and of the
  participants with the smallest TTC (every measure explained in a line), the table of its worst
  events (pair, time, kind, value ± std, collision probability) and a figure of each of the first
  of them (:func:`event_figure`). ``report_html.render_html`` places it after the summary.
- :func:`event_figure`: one event on a page: the two paths on the map around the event (the
  footprints at its extreme, the stretch while it was critical drawn thick) and the pair's TTC and
  DRAC over time with their 1-sigma bands, the time axis within the recording.
"""

from __future__ import annotations

import base64
import html
from typing import Any

import numpy as np

#: the summary's measures shown, with their std column, unit and the line that explains them
ROWS = (("min TTC", "min_ttc", "min_ttc_std", "s"), ("TET", "tet", "tet_std", "s"),
        ("TIT", "tit", "tit_std", "s²"), ("max DRAC", "max_drac", "max_drac_std", "m/s²"),
        ("min PSD", "min_psd", "min_psd_std", ""), ("min PET", "min_pet", "min_pet_std", "s"),
        ("CPI", "cpi", "cpi_std", "%"))
#: how many of the worst events get a figure in the report
FIGURES = 3


def _pm(v: Any, sd: Any, unit: str = "") -> str:
    if v is None:
        return "–"
    if unit == "%":
        return cpi_text(v, sd)
    return f"{v:.3g}" + (f" ± {sd:.2g}" if sd is not None else "")


def cpi_text(v: float | None, sd: float | None) -> str:
    """CPI as a percentage of the observed time (``< 0.01 %`` where it and its std are below
    that: the deceleration needed never came near the available one)."""
    if v is None:
        return "–"
    if v < 1e-4 and (sd is None or sd < 1e-4):
        return "< 0.01 %"
    return f"{100 * v:.2f} %" + (f" ± {100 * sd:.2f}" if sd is not None else "")


def _read(rec: Any, name: str, *, participant_ids: list[int] | None = None,
          columns: list[str] | None = None):
    """Table ``name`` of the written recording ``rec`` (only the row groups of the given
    participants, where given), or None when it has none or cannot be read."""
    import pyarrow.parquet as pq

    from aveas_format.io.container import Container

    path = getattr(rec, "path", None)
    entry = rec.meta.tables.get(name) if hasattr(rec, "meta") else None
    if path is None or entry is None:
        return None
    try:
        with Container(path) as c:
            filters = ([("participant_id", "in", list(participant_ids))]
                       if participant_ids is not None else None)
            return pq.read_table(c.input_file(f"{name}.parquet"), columns=columns,
                                 filters=filters)
    except Exception:  # noqa: BLE001 — the section is a bonus of the report
        return None


def _table_of(rec: Any, name: str, *, participant_ids: list[int] | None = None,
              columns: list[str] | None = None):
    """A derived table (``derived/NAME``) or the events, in memory or read from disk."""
    if name == "events":
        t = getattr(rec, "events", None)
        if t is not None:
            return t
        return _read(rec, "events")
    t = rec.derived.get(name.removeprefix("derived/"))
    if t is not None:
        return t
    return _read(rec, name, participant_ids=participant_ids, columns=columns)


def _head(r: dict) -> str:
    return "recording" if r["participant_id"] is None else f"participant {r['participant_id']}"


def _summary_html(cs, participants: int) -> list[str]:
    from aveas_format.derive.events import EXPLAIN

    e = html.escape
    rows = cs.to_pylist()
    whole = next((r for r in rows if str(r["scope"]) == "recording"), None)
    per = sorted((r for r in rows if str(r["scope"]) == "participant" and r["min_ttc"] is not None),
                 key=lambda r: r["min_ttc"])[:participants]
    cols = ([whole] if whole else []) + per
    out = ["<p class='muted'>derived/criticality_summary: the recording and the participants "
           "with the smallest TTC; values ± 1 std (docs/derive.md).</p>",
           "<table><tr><th>measure</th>" + "".join(f"<th>{e(_head(r))}</th>" for r in cols)
           + "</tr>"]
    for label, k, sd, unit in ROWS:
        tip = EXPLAIN.get("CPI") if k == "cpi" else (EXPLAIN.get("TET / TIT")
                                                    if k in ("tet", "tit") else None)
        label_html = (f"<span title='{e(tip)}'>{e(label)}</span>" if tip else e(label))
        out.append(f"<tr><td>{label_html}{f' ({e(unit)})' if unit else ''}</td>" + "".join(
            f"<td class='num'>{e(_pm(r[k], r[sd], unit))}</td>" for r in cols) + "</tr>")
    for label, k in (("samples below the TTC threshold", "ttc_samples_below"),
                     ("conflicts", "conflicts"), ("near misses", "near_misses"),
                     ("hard braking", "hard_braking")):
        out.append(f"<tr><td>{e(label)}</td>" + "".join(
            f"<td class='num'>{r.get(k) if r.get(k) is not None else '–'}</td>" for r in cols)
            + "</tr>")
    out.append("</table>")
    out.append("<p class='muted'>" + "<br>".join(
        f"<b>{e(k)}</b>: {e(v)}" for k, v in EXPLAIN.items() if k in ("CPI", "TET / TIT"))
        + "<br><b>PSD</b>: the remaining distance to the potential collision point over the "
        "minimum stopping distance (below 1: it cannot stop before it).</p>")
    return out


def events_html(worst: list[dict], threshold: float | None = None) -> list[str]:
    """The table of events (:func:`aveas_format.derive.events.worst_events`) as HTML rows with
    the explanation of their columns."""
    from aveas_format.derive.events import EXPLAIN, format_probability, format_value

    e = html.escape
    out = ["<table><tr><th>event</th><th title='" + e(EXPLAIN["kind"]) + "'>kind</th>"
           "<th>pair</th><th>relation</th><th>time (s)</th><th>metric</th>"
           "<th title='" + e(EXPLAIN["value"]) + "'>value ± std</th><th>critical for (s)</th>"
           "<th title='" + e(EXPLAIN["P(collision)"]) + "'>P(collision)</th></tr>"]
    for r in worst:
        pair = ", ".join(str(p) for p in r["participant_ids"] or [])
        t = f"{r['time_start']:.2f}–{r['time_end']:.2f}"
        value = format_value(r.get("metric"), r.get("value"), r.get("value_std"))
        dur = "–" if r.get("duration") is None else f"{r['duration']:.2f}"
        prob = format_probability(r.get("collision_probability"),
                                  r.get("collision_probability_std"))
        out.append(f"<tr><td class='num'><a href='#event-{r['event_id']}'>{r['event_id']}</a></td>"
                   f"<td>{e(r['kind'].replace('_', ' '))}</td><td>{e(pair)}</td>"
                   f"<td>{e(str(r.get('relation') or '–'))}</td><td class='num'>{e(t)}</td>"
                   f"<td>{e(str(r.get('metric') or '–').upper())}</td>"
                   f"<td class='num'>{e(value)}</td><td class='num'>{dur}</td>"
                   f"<td class='num'>{e(prob)}</td></tr>")
    out.append("</table>")
    out.append("<p class='muted'>" + "<br>".join(
        f"<b>{e(k)}</b>: {e(v)}" for k, v in EXPLAIN.items() if k in ("kind", "value",
                                                                       "P(collision)"))
        + (f"<br>TTC threshold {threshold:g} s." if threshold else "") + "</p>")
    return out


def criticality_section(rec: Any, *, participants: int = 5, events: int = 10,
                        figure: bool = True) -> str:
    """HTML: the recording's criticality (module docstring); ``participants``: how many
    participants the summary lists, ``events``: how many events the table lists (the first
    :data:`FIGURES` with a figure)."""
    if rec is None:
        return ""
    from aveas_format.derive.events import worst_events

    cs = _table_of(rec, "derived/criticality_summary")
    ev = _table_of(rec, "events")
    worst = worst_events(ev, events)
    if (cs is None or not cs.num_rows) and not worst:
        return ""
    out = ["<h2>Criticality</h2>"]
    if cs is not None and cs.num_rows:
        out += _summary_html(cs, participants)
    th = rec.meta.thresholds
    thr = th.ttc_s if th is not None and th.ttc_s else None
    out.append("<h3>Worst events</h3>")
    if not worst:
        out.append("<p>No conflicts and no near misses: no pair's TTC, PET or DRAC was beyond "
                   "its threshold with the evidence the data's uncertainty gives "
                   "(docs/derive.md \"Events\").</p>")
        return "\n".join(out)
    out += events_html(worst, thr)
    if figure:
        from aveas_format.plot.recording import png_bytes

        for r in worst[:FIGURES]:
            try:
                fig = event_figure(rec, r)
            except Exception:  # noqa: BLE001 — a figure is a bonus of the report
                continue
            b64 = base64.b64encode(png_bytes(fig)).decode("ascii")
            # the figure's title names the event; the caption says how to read it
            alt = html.escape(event_caption(r))
            out.append(f'<figure id="event-{r["event_id"]}"><img alt="{alt}" '
                       f'src="data:image/png;base64,{b64}"><figcaption>Event {r["event_id"]}: '
                       "the two paths on the map (thick while critical, footprints at the "
                       "event's extreme) and their TTC and DRAC over time, ± 1 std shaded; grey: "
                       "the time the event was critical</figcaption></figure>")
    return "\n".join(out)


def event_caption(r: dict) -> str:
    """A line describing an event row of :func:`aveas_format.derive.events.worst_events`."""
    from aveas_format.derive.events import format_probability, format_value

    a, b = (list(r["participant_ids"]) + [None, None])[:2]
    return (f"Event {r['event_id']}, {r['kind'].replace('_', ' ')}: participants {a} and {b} "
            f"({r.get('relation') or '–'}), {str(r.get('metric') or '').upper()} "
            f"{format_value(r.get('metric'), r.get('value'), r.get('value_std'))} at "
            f"{r.get('time_extreme') or r['time_start']:.2f} s, critical for "
            f"{r.get('duration') or 0:.2f} s, P(collision) "
            f"{format_probability(r.get('collision_probability'), r.get('collision_probability_std'))}")


def _time_range(rec: Any, st) -> tuple[float, float]:
    t = st.column("time").to_numpy() if st is not None and st.num_rows else np.zeros(1)
    d = getattr(rec.meta, "duration_s", None)
    lo = 0.0 if float(t.min()) >= 0 else float(t.min())
    return lo, max(float(t.max()), float(d) if d else 0.0)


def event_figure(rec: Any, event: dict, *, before_s: float = 6.0, after_s: float = 4.0):
    """The figure of one event (module docstring); ``event``: a row of
    :func:`aveas_format.derive.events.worst_events` (or of the events table)."""
    import pyarrow.compute as pc

    from aveas_format.plot._mpl import Figure
    from aveas_format.plot.derive import ttc_drac_figure
    from aveas_format.plot.map import BACKGROUND_LANE_COLORS, plot_map

    a, b = list(event["participant_ids"])[:2]
    t_ref = event.get("time_extreme") or event["time_start"]
    t0 = min(event["time_start"], t_ref) - before_s
    t1 = max(event["time_end"], t_ref) + after_s
    st = rec.states if getattr(rec, "states", None) is not None else None
    if st is None or not ({"participant_id", "x", "y"} <= set(st.column_names)):
        st = _read(rec, "states", participant_ids=[a, b],
                   columns=["participant_id", "time", "x", "y", "heading"])
    st_all = st
    lo, hi = _time_range(rec, st_all)
    t0, t1 = max(t0, lo), min(t1, hi)
    st = st.filter(pc.is_in(st.column("participant_id"), _ids_array([a, b])))
    smooth = _smoothed_positions(rec, a, b)
    it = _table_of(rec, "derived/interactions", participant_ids=[a, b],
                   columns=["participant_id", "time", "other_id", "relation", "ttc", "ttc_std",
                            "ttc_kind", "drac", "drac_std"])
    fig = Figure(figsize=(10, 6.4))
    gs = fig.add_gridspec(2, 2, height_ratios=(1.0, 1.15))
    ax_map = fig.add_subplot(gs[0, :])
    try:
        plot_map(rec.map, ax_map, lane_colors=BACKGROUND_LANE_COLORS, labels=False,
                 legend=False, reference_lines=False, junctions=False, title="")
    except Exception:  # noqa: BLE001 — the paths alone where the map cannot be drawn
        pass
    parts = rec.participants
    sizes = {}
    if parts is not None:
        for row in parts.select(["participant_id", "length", "width"]).to_pylist():
            sizes[row["participant_id"]] = (row["length"] or 4.5, row["width"] or 1.8)
    xs, ys = [], []
    for pid, colour in ((a, "tab:blue"), (b, "tab:red")):
        m = pc.equal(st.column("participant_id"), pid)
        s = st.filter(m)
        t = s.column("time").to_numpy()
        x, y = s.column("x").to_numpy(), s.column("y").to_numpy()
        if pid in smooth:  # the smoothed positions (derived/kinematics) where there are
            ts, xs_, ys_ = smooth[pid]
            x = np.where(np.isfinite(np.interp(t, ts, xs_)), np.interp(t, ts, xs_), x)
            y = np.where(np.isfinite(np.interp(t, ts, ys_)), np.interp(t, ts, ys_), y)
        w = (t >= t0) & (t <= t1)
        crit = (t >= event["time_start"]) & (t <= event["time_end"])
        ax_map.plot(x[w], y[w], "-", color=colour, lw=1.0, label=f"participant {pid}")
        ax_map.plot(x[crit], y[crit], "-", color=colour, lw=3.0, alpha=0.8)
        near = w & (np.abs(t - t_ref) <= 3.0)
        xs += list(x[near])
        ys += list(y[near])
        if len(t):
            k = int(np.argmin(np.abs(t - t_ref)))
            h = s.column("heading").to_numpy()[k] if "heading" in s.column_names else 0.0
            L, W = sizes.get(pid, (4.5, 1.8))
            c, sn = np.cos(h), np.sin(h)
            corners = np.array([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5], [0.5, 0.5]])
            cx = x[k] + corners[:, 0] * L * c - corners[:, 1] * W * sn
            cy = y[k] + corners[:, 0] * L * sn + corners[:, 1] * W * c
            ax_map.fill(cx, cy, color=colour, alpha=0.5, lw=0)
            ax_map.annotate("", (x[k] + 0.7 * L * c, y[k] + 0.7 * L * sn), (x[k], y[k]),
                            arrowprops={"arrowstyle": "->", "color": colour})
    if xs:
        # the paths within 3 s of the extreme, widened to the axes' shape (equal scales)
        pad = 6.0
        pos = ax_map.get_position()
        ratio = (pos.width * fig.get_figwidth()) / max(pos.height * fig.get_figheight(), 1e-9)
        w = max(max(xs) - min(xs) + 2 * pad, (max(ys) - min(ys) + 2 * pad) * ratio)
        cx_, cy_ = 0.5 * (min(xs) + max(xs)), 0.5 * (min(ys) + max(ys))
        ax_map.set_xlim(cx_ - w / 2, cx_ + w / 2)
        ax_map.set_ylim(cy_ - w / ratio / 2, cy_ + w / ratio / 2)
    ax_map.set_aspect("equal", adjustable="box")
    ax_map.set_xlabel("x (m)")
    ax_map.set_ylabel("y (m)")
    ax_map.legend(loc="upper left", fontsize=7)
    ax_map.set_title(f"paths {t0:.1f}–{t1:.1f} s (thick: while critical; footprints at "
                     f"{t_ref:.2f} s)", fontsize=8)
    ax_ttc = fig.add_subplot(gs[1, 0])
    axes = (ax_ttc, fig.add_subplot(gs[1, 1], sharex=ax_ttc))
    if it is not None and it.num_rows:
        ttc_drac_figure(it, a, b, xlim=(t0, t1), axes=axes, span=(event["time_start"],
                                                                  event["time_end"]))
    else:
        axes[0].text(0.5, 0.5, "no TTC of this pair", ha="center", va="center",
                     transform=axes[0].transAxes)
    fig.suptitle(event_caption({**event, "event_id": event.get("event_id", "")}), fontsize=9)
    fig.tight_layout()
    return fig


def _smoothed_positions(rec: Any, a: int, b: int) -> dict[int, tuple]:
    """``{participant: (time, x, y)}`` of derived/kinematics' smoothed positions (empty where it
    has none)."""
    import pyarrow.compute as pc

    k = _table_of(rec, "derived/kinematics", participant_ids=[a, b],
                  columns=["participant_id", "time", "x", "y"])
    if k is None or not {"x", "y"} <= set(k.column_names):
        return {}
    out = {}
    for pid in (a, b):
        s = k.filter(pc.equal(k.column("participant_id"), pid))
        x = s.column("x").to_numpy(zero_copy_only=False).astype(float)
        if s.num_rows and np.isfinite(x).all():
            out[pid] = (s.column("time").to_numpy(), x,
                        s.column("y").to_numpy(zero_copy_only=False).astype(float))
    return out


def reliability_figure(p: np.ndarray, outcome: np.ndarray, edges=(0.0, 0.05, 0.2, 0.4, 0.6, 0.8,
                                                                  1.0), title: str | None = None):
    """Reliability diagram of collision probabilities ``p`` against the outcomes (1: the
    encounter collided): per bin of ``p`` (``edges``) the share that collided (with its 95 %
    Wilson interval) over the bin's mean ``p``, the diagonal, and the events per bin."""
    from aveas_format.derive.events._episodes import wilson
    from aveas_format.plot._mpl import Figure

    p, y = np.asarray(p, float), np.asarray(outcome, float)
    fig = Figure(figsize=(8.5, 3.8))
    ax, ah = fig.subplots(1, 2, gridspec_kw={"width_ratios": (1.2, 1.0)})
    ax.plot([0, 1], [0, 1], "--", color="0.5", lw=1, label="calibrated")
    e = np.asarray(edges, float)
    for lo, hi in zip(e[:-1], e[1:]):
        m = (p >= lo) & ((p < hi) | (hi >= 1.0))
        if not m.any():
            continue
        k, n = float(y[m].sum()), int(m.sum())
        lo_ci, hi_ci = wilson(np.array(k), n)
        mp, fr = float(p[m].mean()), k / n
        ax.errorbar(mp, fr, yerr=[[fr - float(lo_ci)], [float(hi_ci) - fr]], fmt="o",
                    color="tab:red", capsize=3, ms=5)
        ax.annotate(str(n), (mp, fr), textcoords="offset points", xytext=(6, -10), fontsize=7)
    ax.set_xlim(-0.02, 1.02)
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("collision probability (derived, bin mean)")
    ax.set_ylabel("share that collided (truth)")
    ax.set_aspect("equal")
    ax.legend(loc="upper left", fontsize=8)
    ah.hist(p, bins=np.linspace(0, 1, 21), color="tab:red", alpha=0.7)
    ah.set_xlabel("collision probability")
    ah.set_ylabel("events")
    ah.set_yscale("log")
    fig.suptitle(title or f"{len(p)} encounters: reliability (error bars: 95 % Wilson)",
                 fontsize=10)
    fig.tight_layout()
    return fig


def _ids_array(values):
    import pyarrow as pa

    return pa.array(values, pa.int64())


__all__ = ["criticality_section", "cpi_text", "event_caption", "event_figure", "events_html",
           "reliability_figure"]
