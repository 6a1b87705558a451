"""Screenshots of the HTML validation report and the report's figures for docs/validate.md:
``python tools/report_figures.py [OUTDIR]`` (``make docs`` runs it through ``docgen.py --figures``).

The recording is the demo's highway scene (:func:`aveas_format.sample.highway_scene`) with three
defects put in, so that the report has something to show: a car's velocity 1.8 times too high for
0.4 s (kinematics.*), a 19 m car (participants.size_implausible), lane ids that disagree with
road_t (map.lane_mismatch). The page is rendered by headless Chromium (:func:`screenshot`; Debian:
``apt-get install chromium``); without it the screenshots are skipped with one line on stderr.

- ``validate_report.png``: the top of the HTML report (verdict, summary, rules, the map figure).
- ``validate_report_findings.png``: a rule's expanded section with its sampled findings.
- ``validate_map.png``, ``validate_speed.png``, ``validate_acceleration.png``,
  ``validate_sample_rate.png``: the figures (``aveas-format plot``).
- ``opendrive_ramps.png``: a map with entry/exit/onRamp/offRamp lanes (``aveas-format map plot``;
  needs the shared qc-opendrive sample).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa

ROOT = Path(__file__).resolve().parent.parent
RAMPS_MAP = ROOT.parent / "shared" / "data" / "xodr" / "qc-opendrive__Ex_Entry_Exit.xodr"


def find_chromium() -> str | None:
    """The path of a Chromium/Chrome binary, or None."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        path = shutil.which(name)
        if path:
            return path
    return None


def screenshot(html: Path, png: Path, *, width: int = 1280, height: int = 4000,
               crop: bool = True, timeout: float = 120) -> Path:
    """Render ``html`` in headless Chromium into ``png`` (``width`` x ``height`` CSS pixels;
    ``crop`` cuts the empty page below the content). Raises RuntimeError without Chromium or when
    it fails."""
    exe = find_chromium()
    if exe is None:
        raise RuntimeError("chromium not found (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory(prefix="aveas-chromium-") as profile:
        cmd = [exe, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
               "--no-first-run", "--disable-background-networking", "--disable-component-update",
               "--disable-sync", "--hide-scrollbars", f"--user-data-dir={profile}",
               f"--screenshot={png}", f"--window-size={width},{height}", html.resolve().as_uri()]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    if res.returncode != 0 or not png.exists():
        raise RuntimeError(f"chromium failed ({res.returncode}): {res.stderr[-500:]}")
    if crop:
        _crop_blank_bottom(png)
    return png


def _crop_blank_bottom(png: Path, margin: int = 24) -> None:
    from PIL import Image

    with Image.open(png) as im:
        rgb = np.asarray(im.convert("RGB"))
        ink = np.flatnonzero((rgb < 245).any(axis=(1, 2)))
        if len(ink):
            bottom = min(rgb.shape[0], int(ink[-1]) + margin)
            im.crop((0, 0, rgb.shape[1], bottom)).save(png)


def defective_highway():
    """The demo highway with three defects (see the module doc)."""
    from aveas_format.sample import highway_scene

    rec = highway_scene()
    s = rec.states
    pid = s.column("participant_id").to_numpy()
    t = s.column("time").to_numpy()
    ids, n = np.unique(pid, return_counts=True)
    longest = pid == ids[np.argmax(n)]
    t0 = float(np.median(t[longest]))
    vx = s.column("vx").to_numpy().copy()
    vx[longest & (t >= t0) & (t < t0 + 0.4)] *= 1.8
    lane = s.column("lane_id").to_numpy(zero_copy_only=False).copy()
    wrong = np.flatnonzero(pid == pid[len(pid) // 2])[::40]
    lane[wrong] = np.where(lane[wrong] == -1, -2, -1)
    s = s.set_column(s.column_names.index("vx"), "vx", pa.array(vx))
    s = s.set_column(s.column_names.index("lane_id"), "lane_id", pa.array(lane, s.column("lane_id").type))
    p = rec.participants
    length = p.column("length").to_numpy().copy()
    cls = np.asarray(p.column("class").cast(pa.string()).to_pylist())
    length[np.flatnonzero(cls == "car")[3]] = 19.0
    p = p.set_column(p.column_names.index("length"), "length", pa.array(length))
    rec.replace_tables({"states": s, "participants": p})
    return rec


def main(outdir: Path) -> list[Path]:
    import aveas_format
    from aveas_format.plot.recording import open_for_figures, save_figures
    from aveas_format.plot.report_html import render_html
    from aveas_format.safeio import write_text_atomic

    outdir.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    outdir = outdir.resolve()
    cwd = Path.cwd()
    with tempfile.TemporaryDirectory(prefix="aveas-report-") as tmp:
        os.chdir(tmp)  # the report names the recording as a user would type it
        try:
            path = defective_highway().write(Path("highway-defects.aveas"))
            report = aveas_format.validate(path)
            rec = open_for_figures(path, report)
            rec.map  # noqa: B018 — parsed here, inside the directory
        finally:
            os.chdir(cwd)
        for p in save_figures(rec, Path(tmp) / "fig", report.findings()):
            dest = outdir / f"validate_{p.name}"
            shutil.copyfile(p, dest)
            written.append(dest)
        page = Path(tmp) / "report.html"
        write_text_atomic(page, render_html(report, rec))
        if find_chromium() is None:
            print("skipped the report screenshots: chromium not found (Debian: apt-get install "
                  "chromium)", file=sys.stderr)
        else:
            shot = screenshot(page, Path(tmp) / "page.png", height=6000)
            written += _cut(shot, outdir)
    if RAMPS_MAP.exists():
        from aveas_format.opendrive import load_map
        from aveas_format.plot.map import save_map

        written.append(save_map(load_map(RAMPS_MAP), outdir / "opendrive_ramps.png", dpi=100,
                                title="qc-opendrive Ex_Entry_Exit: entry, exit, onRamp, offRamp"))
    return written


def _cut(shot: Path, outdir: Path) -> list[Path]:
    """The top of the page (down to the map figure) and the findings of the first rule."""
    from PIL import Image

    with Image.open(shot) as im:
        rgb = np.asarray(im.convert("RGB")).astype(int)
        # the first rule section: its red left border (#c62828) below the figures
        left = rgb[:, 20:60]
        red = np.flatnonzero(((np.abs(left[..., 0] - 0xC6) < 12) &
                              (np.abs(left[..., 1] - 0x28) < 12)).any(axis=1))
        top_end = min(im.height, 1750)
        start = int(red[red > top_end][0]) - 60 if (red > top_end).any() else top_end
        parts = [(outdir / "validate_report.png", (0, 0, im.width, top_end)),
                 (outdir / "validate_report_findings.png",
                  (0, max(start, 0), im.width, min(im.height, max(start, 0) + 700)))]
        for dest, box in parts:
            im.crop(box).save(dest)
    return [dest for dest, _ in parts]


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "docs" / "figures"
    for p in main(out):
        print(f"wrote {p}", file=sys.stderr)
