"""The HTML validation report (aveas_format.plot.report_html): summary, rule docs and links,
markup, `validate -o DIR/`, and a headless Chromium screenshot."""

from __future__ import annotations

import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import aveas_format
import helpers_validate as vf
from helpers_realdata import real_files, third_party
from aveas_format.plot.report_html import recording_facts, render_html
from aveas_format.validate.render import inline_markup, rule_anchor


@pytest.fixture(scope="module")
def broken():
    sc = vf.fresh()
    sc["tracks"][0]["x"][75:] += 3.0           # kinematics.position_jump (error)
    sc["participants"]["length"][1] = 9.0       # participants.size_implausible (warning)
    rec = vf.build(sc)
    return rec, aveas_format.validate(rec)


def test_inline_markup_is_rendered_or_removed():
    doc = "over ``window_s`` (see :func:`~aveas_format.numeric.wrap_angle`), **not** *per* `row`; 2 * 3"
    assert inline_markup(doc) == "over window_s (see aveas_format.numeric.wrap_angle), not per row; 2 * 3"
    assert inline_markup(doc, html=True) == (
        "over <code>window_s</code> (see <code>aveas_format.numeric.wrap_angle</code>), "
        "<b>not</b> <i>per</i> <code>row</code>; 2 * 3")
    assert inline_markup("a ``<b>`` & c", html=True) == "a <code>&lt;b&gt;</code> &amp; c"
    assert rule_anchor("geo.crs_mismatch") == "geocrs_mismatch"


def test_summary_block_describes_the_recording(broken):
    rec, report = broken
    facts = dict(recording_facts(rec))
    assert facts["Participants"] == "4: 2 car, 1 truck, 1 van"
    assert facts["Duration"] == "5.96 s"
    assert facts["Sample rate"] == "25 Hz nominal, 25 Hz observed (median)"
    assert facts["Map"] == "map.xodr (OpenDRIVE 1.6): 1 roads, 0 junctions"
    assert facts["Coverage"].startswith("0.014 km² (14,000 m²), x 0.0...1,000.0 m")
    assert facts["Provenance"] == "natural" and facts["CRS"] == rec.meta.crs
    assert facts["Acquisition"].startswith("aerial, by Test Institute; drone")
    page = render_html(report, rec)
    summary = page[page.index("<h2>Summary</h2>"):page.index("<h2>Rules with findings</h2>")]
    assert "<th>Participants</th><td>4: 2 car, 1 truck, 1 van</td>" in summary
    assert re.search(r"<div class='count error'><b>1</b>error<br><small>1 rule</small>", summary)
    assert re.search(r"<div class='count warning'><b>1</b>warning<br>", summary)
    assert "<div class='count zero'><b>0</b>info" in summary


def test_rule_codes_carry_their_doc_link_and_no_raw_markup(broken):
    rec, report = broken
    page = render_html(report, rec)
    jump = aveas_format.validate.load_rules()["kinematics.position_jump"]
    assert "``" not in page  # no raw reStructuredText anywhere
    # the table row: tooltip = the plain doc, link = the rule's section in the page
    assert (f"<a href='#kinematicsposition_jump' title='{inline_markup(jump.doc)}'>"
            in page.replace("&#x27;", "'"))
    assert "<details class='rule error' id='kinematicsposition_jump' open>" in page
    assert "<code>jump_tolerance_m</code>" in page
    assert "http://" not in page and "https://" not in page and "<script" not in page
    linked = render_html(report, rec, docs_url="https://example.org/aveas/docs/")
    assert "href='https://example.org/aveas/docs/rules.md#kinematicsposition_jump'" in linked
    assert linked.count("rules.md#participantssize_implausible") == 2  # table and section


def test_title_is_the_recording_name_and_sections_have_a_place(broken):
    rec, report = broken
    page = render_html(report, rec, sections=[("Criticality", "<p>min TTC 1.2 s</p>")])
    assert "<h1>clean recording for the rule tests <span class='badge error'>INVALID" in page
    assert page.index("<h2>Summary</h2>") < page.index("<h2>Criticality</h2><p>min TTC 1.2 s") \
        < page.index("<h2>Rules with findings</h2>")


def test_text_from_the_recording_is_escaped():
    """A title, partner or finding value is data, never markup: a report mailed around must not
    run what a recording wrote into it."""
    sc = vf.fresh()
    sc["meta"]["title"] = "<script>alert(1)</script> 'q' \"d\""
    sc["meta"]["partner"] = "<img src=x onerror=alert(2)>"
    sc["participants"]["source_id"][1] = "</td><script>alert(3)</script>"
    sc["participants"]["length"][1] = 9.0
    rec = vf.build(sc)
    page = render_html(aveas_format.validate(rec), rec)
    assert "<script" not in page and "<img src=x" not in page
    assert "<h1>&lt;script&gt;alert(1)&lt;/script&gt; &#x27;q&#x27; &quot;d&quot; <span" in page
    assert "&lt;img src=x onerror=alert(2)&gt;" in page


def test_the_report_without_matplotlib_has_everything_but_the_figures(broken, tmp_path):
    """matplotlib is the [plot] extra: without it the page is complete, minus the figures, and
    says which extra draws them (a dataset's reports directory is written the same way)."""
    rec, _ = broken
    path = rec.write(tmp_path / "b.aveas")
    code = f"""
import sys
sys.modules["matplotlib"] = None  # as if not installed
import aveas_format
from aveas_format.io.reader import open_recording
from aveas_format.plot.report_html import render_html
rec = open_recording({str(path)!r})
page = render_html(aveas_format.validate(rec), rec)
assert "matplotlib" not in sys.modules or sys.modules["matplotlib"] is None
print(page)
"""
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    page = res.stdout
    assert "<h2>Summary</h2>" in page and "kinematics.position_jump" in page
    assert "No figures: matplotlib, an optional dependency for drawing figures, is not " \
           "installed: pip install &quot;aveas-format[plot]&quot;." in page


def test_report_without_a_readable_recording_says_so(broken):
    _, report = broken
    page = render_html(report, None)
    assert "could not be read for a summary" in page and "No figures" in page


def test_cli_output_directory_writes_json_and_html_and_refuses_to_replace(broken, tmp_path):
    rec, _ = broken
    path = rec.write(tmp_path / "b.aveas")
    out = tmp_path / "report"

    def run(*args):
        return subprocess.run([sys.executable, "-m", "aveas_format", "validate", str(path), *args],
                              capture_output=True, text=True, timeout=300)

    res = run("-o", f"{out}/")
    assert res.returncode == 1, res.stderr
    assert sorted(p.name for p in out.iterdir()) == ["report.html", "report.json"]
    assert aveas_format.validate.Report.from_json((out / "report.json").read_text()).codes == \
        {"kinematics.position_jump", "participants.size_implausible"}
    assert "<h2>Summary</h2>" in (out / "report.html").read_text()
    assert "INVALID" in res.stderr and f"wrote {out / 'report.json'}" in res.stderr
    before = (out / "report.json").read_bytes()
    res = run("-o", str(out))  # an existing directory, no trailing slash
    assert res.returncode == 2 and "report.json: exists; pass --overwrite" in res.stderr
    assert (out / "report.json").read_bytes() == before
    assert run("-o", str(out), "--overwrite").returncode == 1
    single = tmp_path / "r.html"
    assert run("--format", "html", "-o", single).returncode == 1
    res = run("--format", "html", "-o", single)
    assert res.returncode == 2 and "pass --overwrite" in res.stderr


def test_headless_chromium_screenshot_of_the_report(broken, tmp_path):
    """The page renders in a real browser: the verdict badge, the summary cards and the embedded
    map figure are painted (Debian: apt-get install chromium)."""
    import report_figures

    if report_figures.find_chromium() is None:
        pytest.skip("chromium not installed (Debian: apt-get install chromium)")
    from PIL import Image

    rec, report = broken
    page = tmp_path / "report.html"
    page.write_text(render_html(report, rec), encoding="utf-8")
    png = report_figures.screenshot(page, tmp_path / "report.png", width=1280, height=3000)
    with Image.open(png) as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
    assert rgb.shape[1] == 1280 and 1500 < rgb.shape[0] <= 3000  # cropped below the content

    def share(color, rows):
        r, g, b = (int(color[i:i + 2], 16) for i in (1, 3, 5))
        part = rgb[rows]
        return float(((abs(part[..., 0] - r) < 10) & (abs(part[..., 1] - g) < 10)
                      & (abs(part[..., 2] - b) < 10)).mean())

    assert share("#c62828", slice(0, 450)) > 0.002   # INVALID badge + error card
    assert share("#ef6c00", slice(0, 450)) > 0.002   # the warning card
    # the map figure: its lanes (light grey) and the trajectories in the class colours
    from aveas_format.plot.map import BACKGROUND_LANE_COLORS
    from aveas_format.plot.recording import CLASS_COLORS

    below = slice(600, None)
    assert share(BACKGROUND_LANE_COLORS["driving"], below) > 0.05
    assert all(share(CLASS_COLORS[c], below) > 0.0001 for c in ("car", "truck", "van"))


def test_cli_output_directory_of_a_dataset_is_its_reports_dir(broken, tmp_path):
    rec, _ = broken
    (tmp_path / "data").mkdir()
    rec.write(tmp_path / "data" / "a.aveas")
    rec.write(tmp_path / "data" / "b.aveas")
    out = tmp_path / "reports"
    cmd = [sys.executable, "-m", "aveas_format", "validate", str(tmp_path / "data"), "-j", "1",
           "-o", f"{out}/"]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 1, res.stderr
    names = sorted(p.name for p in out.iterdir())
    assert {"dataset-report.html", "dataset-report.json"} <= set(names) and len(names) == 6
    # each recording's report as JSON and as HTML (its summary, no figures), linked from the
    # dataset's page by a relative link (the directory can be moved or mailed as it is)
    pages = [n for n in names if n.startswith(("a-", "b-")) and n.endswith(".html")]
    assert len(pages) == 2 and all(n[:-5] + ".json" in names for n in pages)
    page = (out / pages[0]).read_text()
    assert "<h2>Summary</h2>" in page and "Participants" in page
    assert "No figures: not drawn in a dataset&#x27;s reports" in page
    index = (out / "dataset-report.html").read_text()
    assert all(f"<a href='{n}'>" in index for n in pages)
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert res.returncode == 2 and "dataset-report.json: exists; pass --overwrite" in res.stderr


# --- files other tools wrote ---------------------------------------------------------------------

def _real_recording(path):
    from aveas_format.converters import convert
    from helpers_common import STRAIGHT_MAP

    if path.suffix == ".gz":  # SUMO's FCD of its default lane-change run, on its own network
        run = path.parent
        return convert("sumo-fcd", [path], map_source=run / "road.xodr",
                       options={"vtypes": [run / "r.rou.xml"]})
    with warnings.catch_warnings():  # the converter's note of a skipped DontCare label
        warnings.simplefilter("ignore", UserWarning)
        return convert("openlabel", [path], map_source=STRAIGHT_MAP)  # KITTI: no map of theirs


@pytest.mark.parametrize("path", [
    *real_files("real/sumo/fcd_default_lanechanges.xml.gz"),
    *third_party("vcd__openlabel100_kitti_tracking_0016_excerpt.json"),
])
def test_report_of_a_real_recording(path, tmp_path):
    """The report of a file SUMO / KITTI wrote: the summary counts its participants per class, the
    four figures are drawn, the map figure frames the data (KITTI's dozen people and cars near the
    camera, not the 1000 m stand-in road), every finding has its rule's section."""
    from aveas_format.plot.recording import map_figure

    rec = _real_recording(path)
    report = aveas_format.validate(rec)
    page = render_html(report, rec)
    classes = dict(zip(*np.unique(np.asarray(rec.participants.column("class").to_pylist()),
                                  return_counts=True)))
    facts = dict(recording_facts(rec))
    assert facts["Participants"].startswith(f"{rec.participants.num_rows:,}: ")
    assert all(f"{n:,} {c}" in facts["Participants"] for c, n in classes.items())
    assert page.count("<img alt=") == 4 and "No figures" not in page
    assert all(f"id='{rule_anchor(r.code)}'" in page for r in report.results)
    x = np.asarray(rec.states.column("x"))
    lims = np.array([ax.get_xlim() for ax in map_figure(rec).axes])  # one strip or several
    x0, x1 = lims[:, 0].min(), lims[:, 1].max()
    assert x0 <= x.min() and x1 >= x.max() and (x1 - x0) < 2 * (x.max() - x.min()) + 60
