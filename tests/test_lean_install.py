"""The lean core install (``pip install aveas-format``, no extras): reading, validating, deriving
and the CLI work without the optional stacks, and each command that needs one says which extra
in one line (exit 3). Simulated by a subprocess in which the extras' packages cannot be imported
(a meta path finder refuses them), so the test needs no second environment."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from helpers_common import STRAIGHT_MAP

#: the top-level packages of every extra ([fast], [plot], [mcap], [ros2], [osi], [dask], [sim], [fit])
EXTRAS = ("orjson", "matplotlib", "mcap", "mcap_ros2", "rosbags", "foxglove_schemas_protobuf", "google",
          "betterosi", "dask", "distributed", "sklearn", "sumo", "sumolib", "traci")

SCRIPT = textwrap.dedent('''
    import contextlib, io, json, sys

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ModuleNotFoundError(f"No module named {name!r}", name=name)

    BLOCKED = set(json.loads(sys.argv[1]))
    sys.meta_path.insert(0, Block())
    import aveas_format
    from aveas_format.cli.app import app
    from aveas_format.cli.common import run
    from aveas_format.derive import derive

    results = {}
    rec = aveas_format.open(sys.argv[2])
    derive(rec)
    derived = rec.write(sys.argv[2] + ".derived.aveas")
    results["api"] = [aveas_format.validate(derived).exit_code(), sorted(rec.derived)]
    for key, args in json.loads(sys.argv[3]).items():
        out, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = run(app, args)
        results[key] = [code, out.getvalue(), err.getvalue()]
    results["loaded"] = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
    print("RESULTS " + json.dumps(results))
''')


def test_the_core_works_and_each_extra_is_named(tmp_path):
    from helpers_common import small_recording

    rec = small_recording().write(tmp_path / "r.aveas")
    (tmp_path / "fcd.xml").write_text(
        '<fcd-export><timestep time="0"><vehicle id="a" x="10" y="-1.75" angle="90" speed="20"/>'
        '</timestep><timestep time="0.1"><vehicle id="a" x="12" y="-1.75" angle="90" speed="20"/>'
        '</timestep></fcd-export>')
    runs = {
        "info": ["info", str(rec), "--format", "json"],
        "validate": ["validate", str(rec), "--format", "json"],
        "list": ["convert", "--list", "--format", "json"],
        "convert": ["convert", "--from", "sumo-fcd", str(tmp_path / "fcd.xml"), "--map",
                    str(STRAIGHT_MAP), "-o", str(tmp_path / "c.aveas"), "-O", "partner=t", "-O",
                    "license=CC0-1.0"],
        "openlabel": ["export", "--to", "openlabel", str(rec), "-o", str(tmp_path / "r.json")],
        "html": ["validate", str(rec), "--format", "html", "-o", str(tmp_path / "r.html")],
        "plot": ["plot", str(rec), "-o", str(tmp_path / "figs")],
        "map_plot": ["map", "plot", str(STRAIGHT_MAP), "-o", str(tmp_path / "m.png")],
        "mcap": ["export", "--to", "mcap", str(rec), "-o", str(tmp_path / "r.mcap")],
        "osi": ["export", "--to", "osi", str(rec), "-o", str(tmp_path / "t.osi")],  # + t.xodr
        "ros2": ["convert", "--from", "ros2-mcap", str(tmp_path / "fcd.xml"), "--map",
                 str(STRAIGHT_MAP), "-o", str(tmp_path / "v.aveas"), "-O", "partner=t", "-O",
                 "license=CC0-1.0"],
        "dask": ["validate", str(rec), str(rec), "--scheduler", "tcp://127.0.0.1:1"],
        "demo": ["demo", "-o", str(tmp_path / "demo"), "--vehicles", "3", "--duration", "2"],
    }
    res = subprocess.run([sys.executable, "-c", SCRIPT, json.dumps(EXTRAS), str(rec),
                          json.dumps(runs)], capture_output=True, text=True, timeout=600)
    line = next((s for s in res.stdout.splitlines() if s.startswith("RESULTS ")), None)
    assert line, res.stdout[-3000:] + res.stderr[-3000:]
    r = json.loads(line[len("RESULTS "):])
    assert r["api"][0] == 0 and "kinematics" in r["api"][1]
    for key in ("info", "validate", "list"):
        assert r[key][0] == 0 and json.loads(r[key][1]), r[key]
    for key in ("convert", "openlabel"):
        assert r[key][0] == 0, (key, r[key])
    # the HTML report renders without matplotlib, minus the figures, and names the extra that draws them
    assert r["html"][0] == 0, r["html"]
    assert 'pip install &quot;aveas-format[plot]&quot;' in (tmp_path / "r.html").read_text()
    for key, extra in (("plot", "plot"), ("map_plot", "plot"), ("mcap", "mcap"),
                       ("osi", "osi"), ("ros2", "ros2"), ("dask", "dask")):
        code, _, err = r[key]
        assert code == 3 and len(err.strip().splitlines()) == 1, (key, r[key])
        assert err.strip().endswith(f'pip install "aveas-format[{extra}]"'), (key, err)
    assert not (tmp_path / "figs").exists()
    code, out, err = r["demo"]  # the demo skips what needs an extra, and says so
    assert code == 0, err
    assert 'skipped the mcap export: ' in err and '"aveas-format[plot]"' in err
    assert (tmp_path / "demo" / "highway.aveas").is_dir()
    assert r["loaded"] == []  # no extra was imported behind the blocker's back
