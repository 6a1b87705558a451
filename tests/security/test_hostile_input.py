"""Hostile input: XML entity attacks, zip slip, zip bombs, JSON bombs, killed writers."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

import aveas_format
from aveas_format.errors import AveasError, FormatError, MapError, RecordingIOError
from aveas_format.opendrive import load_map
from aveas_format.safeio import load_json

from helpers_common import STRAIGHT_MAP


def _xodr_with_doctype(doctype: str, body_ref: str) -> bytes:
    base = STRAIGHT_MAP.read_text()
    base = base.replace('<?xml version="1.0" encoding="UTF-8"?>\n',
                        f'<?xml version="1.0" encoding="UTF-8"?>\n{doctype}\n')
    return base.replace('name="straight-test"', f'name="{body_ref}"').encode()


def test_external_entity_is_not_resolved(tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("TOP-SECRET-CONTENT")
    data = _xodr_with_doctype(f'<!DOCTYPE OpenDRIVE [<!ENTITY xxe SYSTEM "file://{secret}">]>',
                              "&xxe;")
    try:
        net = load_map(data)
    except MapError:
        return  # refusing is fine too
    assert "TOP-SECRET" not in (net.header.name or "")


def test_entity_expansion_bomb_is_refused_quickly():
    lol = '<!ENTITY a0 "lollollollollollollollollollol">' + "".join(
        f'<!ENTITY a{i} "{("&a" + str(i - 1) + ";") * 10}">' for i in range(1, 12))
    data = _xodr_with_doctype(f"<!DOCTYPE OpenDRIVE [{lol}]>", "&a11;")
    t0 = time.perf_counter()
    try:
        net = load_map(data)
        assert len(net.header.name or "") < 1_000_000
    except MapError:
        pass
    assert time.perf_counter() - t0 < 5.0


def test_zip_slip_member_is_refused(tmp_path, written):
    z = tmp_path / "evil.aveas.zip"
    with zipfile.ZipFile(z, "w") as zf:
        for f in Path(written).iterdir():
            zf.write(f, f.name)
        zf.writestr("../../outside.txt", "pwned")
    with pytest.raises(RecordingIOError, match="unsafe path"):
        aveas_format.open(z)
    assert not (tmp_path.parent / "outside.txt").exists()
    with pytest.raises(RecordingIOError, match="unsafe path"):
        aveas_format.validate(z)


def test_zip_bomb_member_is_refused(tmp_path, written):
    z = tmp_path / "bomb.aveas.zip"
    with zipfile.ZipFile(z, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for f in Path(written).iterdir():
            zf.write(f, f.name)
        zf.writestr("derived/padding.bin", b"\0" * (64 * 1024 * 1024))
    with pytest.raises(RecordingIOError, match="compression ratio"):
        aveas_format.open(z)


def test_truncated_zip(tmp_path, rec):
    z = rec.write(tmp_path / "t.aveas.zip")
    z.write_bytes(z.read_bytes()[:-200])
    with pytest.raises(AveasError):
        aveas_format.open(z)


def test_json_limits():
    with pytest.raises(FormatError, match="nested deeper than 64"):
        load_json(b"[" * 5000 + b"]" * 5000)
    with pytest.raises(FormatError, match="nested deeper"):
        load_json(b"[" * 100 + b"]" * 100)
    with pytest.raises(FormatError, match="exceeds the limit"):
        load_json(b" " * 100, max_bytes=10)


def test_deeply_nested_recording_json(written):
    meta = json.loads((written / "recording.json").read_text())
    deep: dict = {}
    cur = deep
    for _ in range(200):
        cur["x"] = {}
        cur = cur["x"]
    meta["extras"] = deep
    (written / "recording.json").write_text(json.dumps(meta))
    with pytest.raises(FormatError, match="nested deeper"):
        aveas_format.open(written)


_WRITER = """
import sys
sys.path.insert(0, {tests!r})
from helpers_common import small_recording
rec = small_recording(n=400, steps=2500)
print("ready", flush=True)
while True:
    rec.write({target!r}, overwrite=True)
    print("wrote", flush=True)
"""


def test_sigkill_during_write_leaves_old_or_new(tmp_path):
    """A writer killed with SIGKILL at any moment leaves a complete recording under the target
    name (the old or the new one), never a partial one."""
    target = tmp_path / "victim.aveas"
    code = _WRITER.format(tests=str(Path(__file__).resolve().parents[1]), target=str(target))
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        assert proc.stdout.readline().strip() == "wrote"  # one complete recording exists
        for delay in (0.05, 0.13, 0.21):
            time.sleep(delay)
            rec = aveas_format.open(target)  # readable at any time, even mid-rewrite
            assert rec.states.num_rows == 1_000_000
    finally:
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    rec = aveas_format.open(target)
    assert rec.states.num_rows == 1_000_000
    assert aveas_format.validate(target, select=["structure"]).counts["error"] == 0
    assert not [p for p in tmp_path.iterdir() if p.name != "victim.aveas" and ".old-" in p.name]
