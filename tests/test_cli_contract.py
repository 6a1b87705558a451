"""The CLI contract of docs/cli.md, walked over every command of the typer app (a new command is
in these tests without a line here, or fails until it gets one): a usage error exits 2 with one
line on stderr, a wrong option value names the closest allowed one, outputs (companion files
included) are never replaced without ``--overwrite``, a closed pipe is a silent exit 0,
``--format json`` parses, output off a terminal is plain.

Most runs are in-process (:func:`aveas_format.cli.common.run` is what the ``aveas-format`` script
runs, with pytest's captured, non-terminal stdout); the pipe tests run the real script.
"""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys

import pytest
import typer.main

from aveas_format.cli.app import app
from aveas_format.cli.common import run

from helpers_common import STRAIGHT_MAP


def leaf_commands(group=None, prefix: tuple[str, ...] = ()) -> dict[tuple[str, ...], object]:
    """Every command of the app (groups resolved to their subcommands), by its path."""
    group = group or typer.main.get_command(app)
    found = {}
    for name, cmd in group.commands.items():
        if getattr(cmd, "commands", None):
            found.update(leaf_commands(cmd, (*prefix, name)))
        else:
            found[(*prefix, name)] = cmd
    return found


COMMANDS = leaf_commands()
IDS = [" ".join(p) for p in COMMANDS]


def options_of(path: tuple[str, ...]) -> set[str]:
    return {o for p in COMMANDS[path].params for o in getattr(p, "opts", ())}


def cli(capsys, *args) -> tuple[int, str, str]:
    code = run(app, [str(a) for a in args])
    res = capsys.readouterr()
    return code, res.out, res.err


def one_error_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aveas-format: error: "), err
    assert "Traceback" not in err and "╭" not in err
    return lines[0]


FCD = """<fcd-export>
<timestep time="0.00"><vehicle id="a" x="10.0" y="-1.75" angle="90.0" type="car" speed="20.0"/></timestep>
<timestep time="0.10"><vehicle id="a" x="12.0" y="-1.75" angle="90.0" type="car" speed="20.0"/></timestep>
<timestep time="0.20"><vehicle id="a" x="14.0" y="-1.75" angle="90.0" type="car" speed="20.0"/></timestep>
</fcd-export>
"""


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """Inputs of every command: a recording, the straight test map, points, an FCD file."""
    from helpers_common import small_recording

    d = tmp_path_factory.mktemp("contract")
    rec = small_recording().write(d / "rec.aveas")
    from aveas_format.derive import derive

    derived = small_recording()
    derive(derived)  # `find` ranks the derived criticality summaries
    derived = derived.write(d / "derived.aveas")
    (d / "points.csv").write_text("x,y\n10,-1.75\n20,-5.25\n")
    (d / "fcd.xml").write_text(FCD)
    bare = re.sub(r"<geoReference>.*?</geoReference>", "", STRAIGHT_MAP.read_text(), flags=re.S)
    (d / "bare.xodr").write_text(bare)  # a map without geoReference: the CRS must be given
    from helpers_lanelet2 import crossroads
    from helpers_mapbuild import highd_like

    (d / "site.osm").write_text(crossroads()[0])  # a Lanelet2 map (map convert)
    t = highd_like(60, duration=120, seed=1)  # tracks (map build)
    (d / "tracks.csv").write_text("track_id,time,x,y\n" + "".join(
        f"{a},{b:.3f},{c:.3f},{e:.3f}\n" for a, b, c, e in zip(t["track"], t["time"], t["x"], t["y"])))
    return {"REC": rec, "MAP": STRAIGHT_MAP, "PTS": d / "points.csv", "FCD": d / "fcd.xml",
            "BARE": d / "bare.xodr", "DERIVED": derived, "OSM": d / "site.osm", "TRACKS": d / "tracks.csv",
            "XODR_OUT": d / "out.xodr"}


def fill(args, env, **extra) -> list[str]:
    values = {**env, **extra}
    return [str(values.get(a, a)) for a in args]


# ---------------------------------------------------------------------------------------------
# usage errors: exit 2, one line on stderr
@pytest.mark.parametrize("path", COMMANDS, ids=IDS)
def test_an_unknown_option_is_a_one_line_usage_error(capsys, path):
    code, out, err = cli(capsys, *path, "--no-such-option")
    assert code == 2
    assert "No such option: --no-such-option" in one_error_line(err)
    assert f"see 'aveas-format {' '.join(path)} --help'" in err


@pytest.mark.parametrize("args,needle", [
    (("convert", "--from", "sumofcd", "FCD", "-o", "OUT"), "(did you mean 'sumo-fcd'?)"),
    (("convert", "--from", "sumo-fcd", "FCD", "-o", "OUT", "-O", "partner=x", "-O", "license=y"),
     "needs a map: pass --map"),
    (("convert", "--from", "sumo-fcd", "FCD", "--map", "MAP", "-o", "OUT", "-O", "net_ofset=1"),
     "net_ofset: Extra inputs are not permitted (did you mean 'net_offset'?)"),
    (("convert", "--from", "sumo-fcd", "FCD", "--map", "MAP", "-o", "OUT", "-O", "net_offset=1"),
     "option net_offset: expected a comma-separated list of 2 numbers, got '1'"),
    (("export", "--to", "openlabl", "REC", "-o", "OUT"), "(did you mean 'openlabel'?)"),
    (("export", "--to", "openlabel", "REC", "-o", "OUT", "-O", "indnet=2"), "(did you mean 'indent'?)"),
    (("validate", "REC", "--format", "htm"), "(did you mean 'html'?)"),
    (("validate", "REC", "--fail-on", "warnings"), "(did you mean 'warning'?)"),
    (("info", "REC", "--format", "jsn"), "(did you mean 'json'?)"),
    (("map", "check", "MAP", "-f", "jason"), "(did you mean 'json'?)"),
    (("convert", "--list", "--format", "josn"), "(did you mean 'json'?)"),
    (("validate", "REC", "--fromat", "json"), "--format"),
    (("validate", "REC", "--select", "kinematic.speed"), "(did you mean 'kinematics.speed'?)"),
    (("derive", "REC", "-o", "OUT", "--only", "kinematic"), "(did you mean 'kinematics'?)"),
    (("derive", "REC", "-o", "OUT", "--window", "60", "--only", "traffic"),
     "--only traffic is not derived by windows"),
    (("derive", "REC", "REC", "-o", "OUT", "--window", "60"), "--window derives one recording"),
    (("derive", "REC", "-o", "OUT", "--window", "0.5"), "--window"),
    (("sim", "run", "-o", "OUT"), "does not state the licence; pass -O license=LICENCE"),
    (("sim", "run", "-o", "OUT", "-O", "licence=CC0-1.0"), "(did you mean 'license'?)"),
    (("convert", "--from", "sumo-fcd", "FCD", "--map", "BARE", "-o", "OUT", "-O", "partner=x", "-O",
      "license=y"), "the map has no <geoReference>, so the recording's CRS must be given"),
    (("frobnicate",), "No such command 'frobnicate'"),
    (("info",), "Missing argument"),
    (("validate", "REC", "-o", "/nonexistent/dir/r.html"), "the directory /nonexistent/dir does not exist"),
    # a submitted file: the converter's usage errors, before any work
    (("validate", "FCD"), "needs a map: pass --map"),
    (("validate", "--from", "sumofcd", "FCD"), "(did you mean 'sumo-fcd'?)"),
    (("validate", "FCD", "--map", "MAP", "-O", "net_ofset=1"), "(did you mean 'net_offset'?)"),
    (("validate", "FCD", "--map", "MAP", "--select", "source.osx"), "unknown rule or family"),
    (("validate", "FCD", "--map", "BARE"), "aveas-format validate --from sumo-fcd"),
])
def test_usage_errors_exit_2_in_one_line(capsys, env, tmp_path, args, needle):
    code, out, err = cli(capsys, *fill(args, env, OUT=tmp_path / "out.aveas"))
    assert code == 2, err
    assert needle in one_error_line(err)
    assert not (tmp_path / "out.aveas").exists()


def test_unstated_values_are_one_warning_for_every_importer(capsys, env, tmp_path):
    """The one rule (issue 42): an import whose source and options do not state the licence (or
    partner, start time) goes ahead with a stand-in the validator warns about, and says so in one
    warning naming each missing value and the -O that states it."""
    out = tmp_path / "f.aveas"
    code, _, err = cli(capsys, "convert", "--from", "sumo-fcd", env["FCD"], "--map", env["MAP"],
                       "-o", out, "--no-validate")
    assert code == 0, err
    warned = [ln for ln in err.splitlines() if "does not state" in ln]
    assert len(warned) == 1 and "-O license=LICENCE" in warned[0], err
    import aveas_format

    assert aveas_format.open(out).meta.rights.license == "unspecified"


class BlockImports:
    """A meta path finder that makes the given top-level packages not installed."""

    def __init__(self, *names: str) -> None:
        self.names = names

    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in self.names:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


def test_a_missing_optional_dependency_names_the_extra(capsys, env, tmp_path, monkeypatch):
    """Each guarded import says which extra to install, in one line (exit 3)."""
    for name in [m for m in sys.modules if m == "mcap" or m.startswith("mcap.")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "meta_path", [BlockImports("mcap"), *sys.meta_path])
    code, out, err = cli(capsys, "export", "--to", "mcap", env["REC"], "-o", tmp_path / "r.mcap")
    assert code == 3
    assert one_error_line(err).endswith('mcap, an optional dependency for the mcap export, is not '
                                        'installed: pip install "aveas-format[mcap]"')


# ---------------------------------------------------------------------------------------------
# outputs: never replaced without --overwrite
#: how to make each command write its output OUT (an existing file or a non-empty directory)
OUTPUT_RUNS: dict[tuple[str, ...], tuple[tuple[str, ...], str]] = {
    ("catalog",): (("catalog", "REC", "-o", "OUT"), "out.parquet"),
    ("convert",): (("convert", "--from", "sumo-fcd", "FCD", "--map", "MAP", "-o", "OUT", "-O",
                    "partner=test", "-O", "license=CC-BY-4.0"), "out.aveas"),
    ("demo",): (("demo", "-o", "OUT", "--vehicles", "3", "--duration", "2"), "dir/"),
    ("derive",): (("derive", "REC", "-o", "OUT"), "out.aveas"),
    ("export",): (("export", "--to", "openlabel", "REC", "-o", "OUT"), "out.json"),
    ("map", "build"): (("map", "build", "TRACKS", "-o", "OUT"), "out.xodr"),
    ("map", "convert"): (("map", "convert", "OSM", "-o", "OUT"), "out.xodr"),
    ("map", "plot"): (("map", "plot", "MAP", "-o", "OUT"), "out.png"),
    ("map", "project"): (("map", "project", "MAP", "-p", "PTS", "-o", "OUT"), "out.csv"),
    ("plot",): (("plot", "REC", "-o", "OUT"), "dir/"),
    ("sim", "run"): (("sim", "run", "-o", "OUT", "-O", "license=CC0-1.0"), "out.aveas"),
    ("sim", "sensitivity"): (("sim", "sensitivity", "-o", "OUT"), "dir/"),
    ("validate",): (("validate", "REC", "-o", "OUT"), "report.txt"),
}
#: commands whose --output is not replaced but resumed, by design (docs/fitting.md)
RESUMED = {("fit", "car-following"), ("fit", "desired-speed"), ("fit", "study")}


def test_every_command_with_an_output_is_covered():
    with_output = {p for p in COMMANDS if "--output" in options_of(p)}
    assert with_output == set(OUTPUT_RUNS) | RESUMED


@pytest.mark.parametrize("path", sorted(OUTPUT_RUNS), ids=[" ".join(p) for p in sorted(OUTPUT_RUNS)])
def test_outputs_are_not_replaced_without_overwrite(capsys, env, tmp_path, path):
    args, kind = OUTPUT_RUNS[path]
    if kind.endswith("/"):
        out = tmp_path / "out"
        out.mkdir()
        (out / "mine.txt").write_text("keep me")
        guarded = out / "mine.txt"
    else:
        out = guarded = tmp_path / kind
        guarded.write_text("keep me")
    code, _, err = cli(capsys, *fill(args, env, OUT=out))
    assert code == 2, err
    line = one_error_line(err)
    assert "--overwrite" in line and str(out) in line
    assert guarded.read_text() == "keep me"
    assert "--overwrite" in options_of(path)


def test_companion_files_are_outputs_too(capsys, env, tmp_path):
    """``export --to openlabel -o k.json`` writes k.xodr next to it: an existing k.xodr is not
    replaced either; with --overwrite both are written."""
    (tmp_path / "k.xodr").write_text("my map")
    code, _, err = cli(capsys, "export", "--to", "openlabel", env["REC"], "-o", tmp_path / "k.json")
    assert code == 2 and f"{tmp_path / 'k.xodr'}: exists; pass --overwrite" in one_error_line(err)
    assert not (tmp_path / "k.json").exists() and (tmp_path / "k.xodr").read_text() == "my map"
    code, _, err = cli(capsys, "export", "--to", "openlabel", env["REC"], "-o", tmp_path / "k.json",
                       "--overwrite")
    assert code == 0, err
    assert (tmp_path / "k.xodr").read_bytes() == STRAIGHT_MAP.read_bytes()


# ---------------------------------------------------------------------------------------------
# --format json
#: how to run each command that has --format json
JSON_RUNS: dict[tuple[str, ...], tuple[str, ...]] = {
    ("convert",): ("convert", "--list"),
    ("export",): ("export", "--list"),
    ("find",): ("find", "DERIVED"),
    ("info",): ("info", "REC"),
    ("map", "build"): ("map", "build", "TRACKS", "-o", "XODR_OUT", "--overwrite"),
    ("map", "check"): ("map", "check", "MAP"),
    ("map", "convert"): ("map", "convert", "OSM", "--origin", "49,8.4", "-o", "XODR_OUT", "--overwrite"),
    ("map", "info"): ("map", "info", "MAP"),
    ("validate",): ("validate", "REC"),
}


def _has_json_format(path) -> bool:
    from aveas_format.cli.common import _choices

    return any("--format" in getattr(p, "opts", ()) and "json" in _choices(p)
               for p in COMMANDS[path].params)


def test_every_json_format_is_covered():
    assert {p for p in COMMANDS if _has_json_format(p)} == set(JSON_RUNS)


@pytest.mark.parametrize("path", sorted(JSON_RUNS), ids=[" ".join(p) for p in sorted(JSON_RUNS)])
def test_format_json_parses(capsys, env, path):
    code, out, err = cli(capsys, *fill(JSON_RUNS[path], env), "--format", "json")
    assert code == 0, err
    assert json.loads(out)


def test_validate_a_submitted_file_in_json(capsys, env):
    """``validate FILE`` (a file a converter imports): the report in JSON, named after the file,
    the import's findings among the rules that ran."""
    code, out, err = cli(capsys, "validate", env["FCD"], "--map", env["MAP"], "--format", "json")
    rep = json.loads(out)
    assert code == 0 and rep["recording"] == str(env["FCD"]), err  # warnings only
    assert "source.other" in rep["rules_run"] and "kinematics.speed" in rep["rules_run"]


def test_the_old_json_flag_still_works_with_a_note(capsys, env):
    code, out, err = cli(capsys, "info", env["REC"], "--json")
    assert code == 0 and json.loads(out)["recording_id"] == "test-1"
    assert "--json is deprecated; use --format json" in err


def test_listings_in_json_name_every_converter(capsys):
    code, out, _ = cli(capsys, "convert", "--list", "--format", "json")
    rows = json.loads(out)
    assert {"sumo-fcd", "ros2-mcap", "openlabel"} <= {r["name"] for r in rows}
    ros2 = next(r for r in rows if r["name"] == "ros2-mcap")
    assert ros2["extra"] == "ros2" and isinstance(ros2["available"], bool)


# ---------------------------------------------------------------------------------------------
# plain output when not a terminal
def test_listings_off_a_terminal_are_plain(capsys):
    code, out, _ = cli(capsys, "convert", "--list")
    assert code == 0
    assert not set(out) & set("┃│━─╇…")  # no rich boxes, nothing cut
    assert "driving-simulator" in out and "infra-lidar" in out and "rotated-boxes" in out


@pytest.mark.parametrize("path", COMMANDS, ids=IDS)
def test_help_off_a_terminal_is_plain_and_whole(capsys, path):
    code, out, _ = cli(capsys, *path, "--help")
    assert code == 0
    assert not set(out) & set("╭│╰…")
    for opt in options_of(path):
        if opt.startswith("--") and not any(p.hidden for p in COMMANDS[path].params
                                            if opt in getattr(p, "opts", ())):
            assert opt in out, f"{opt} missing or cut in the help of {' '.join(path)}"


# ---------------------------------------------------------------------------------------------
# a closed pipe
class _ClosedPipeBytes(io.RawIOBase):
    def writable(self):
        return True

    def write(self, b):
        raise BrokenPipeError(32, "Broken pipe")


class _ClosedPipe(io.TextIOBase):
    """stdout whose reader has gone (``| head``): every write raises EPIPE, text or bytes."""

    buffer = _ClosedPipeBytes()

    def write(self, s):
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        pass

    def isatty(self):
        return False


PIPED: list[tuple[str, ...]] = [
    ("info", "REC"), ("info", "REC", "--format", "json"), ("validate", "REC"),
    ("validate", "FCD", "--map", "MAP"),
    ("validate", "REC", "--format", "json"), ("schema",), ("schema", "--tables"), ("convert", "--list"),
    ("export", "--list", "--format", "json"), ("map", "info", "MAP"), ("map", "check", "MAP"),
    ("map", "project", "MAP", "-p", "PTS"), ("--help",), *[(*p, "--help") for p in COMMANDS],
]


@pytest.mark.parametrize("args", PIPED, ids=[" ".join(a) for a in PIPED])
def test_a_closed_pipe_is_a_silent_exit_0(capsys, env, monkeypatch, args):
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    code = run(app, fill(args, env))
    assert code == 0
    assert capsys.readouterr().err == ""


def _script(*args) -> list[str]:
    return [sys.executable, "-m", "aveas_format", *map(str, args)]


@pytest.mark.parametrize("args", [("info", "REC", "--format", "json"), ("schema", "--tables"),
                                  ("convert", "--list")])
def test_a_real_pipe_into_head_is_silent(env, args):
    """``aveas-format ... | head -1`` (the real script, a real pipe), and the same with the
    reader gone before the first write: exit 0, nothing on stderr."""
    cmd = _script(*fill(args, env))
    writer = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    head = subprocess.run(["head", "-1"], stdin=writer.stdout, capture_output=True, timeout=120)
    writer.stdout.close()
    err = writer.stderr.read().decode()
    assert writer.wait(timeout=120) == 0 and err == "", err
    assert head.stdout.strip()
    r, w = os.pipe()
    os.close(r)
    try:
        res = subprocess.run(cmd, stdout=w, stderr=subprocess.PIPE, timeout=120)
    finally:
        os.close(w)
    assert res.returncode == 0 and res.stderr == b"", res.stderr


# ---------------------------------------------------------------------------------------------
# one meaning of --workers
def test_workers_mean_and_default_the_same_everywhere():
    seen = {}
    for path, cmd in COMMANDS.items():
        for p in cmd.params:
            if "--workers" in getattr(p, "opts", ()):
                seen[path] = (tuple(sorted(p.opts)), p.default,
                              (p.help or "").split(": ")[-1].lower())
    assert len(seen) >= 6, seen
    assert len(set(seen.values())) == 1, seen
    assert next(iter(seen.values()))[:2] == (("--workers", "-j"), 0)


# ---------------------------------------------------------------------------------------------
# a user's second hour (issue 42): what the words say is what happens
def test_fail_on_warning_does_not_say_valid_alone(capsys, env):
    code, out, _ = cli(capsys, "validate", env["REC"], "--fail-on", "warning")
    last = out.strip().splitlines()[-1]
    n = int(re.search(r"(\d+) warnings, 0 info", last).group(1))
    assert code == 1 and n > 0
    assert f": VALID with {n} warnings, failing at --fail-on warning (exit 1) — 0 errors" in last, last
    code, out, _ = cli(capsys, "validate", env["REC"])
    assert code == 0 and f": VALID — 0 errors, {n} warnings" in out.strip().splitlines()[-1]


@pytest.mark.parametrize("fmt", ["json", "html", "text"])
def test_a_report_written_to_a_file_is_named_in_one_line(capsys, env, tmp_path, fmt):
    out_file = tmp_path / f"report.{fmt}"
    code, out, err = cli(capsys, "validate", env["REC"], "--format", fmt, "-o", out_file)
    assert code == 0 and out == "" and out_file.stat().st_size
    assert len(err.strip().splitlines()) == 1, err
    assert err.strip().endswith(f"; wrote {out_file}") and ": VALID — 0 errors" in err


def test_a_finding_names_its_place_once(capsys, tmp_path):
    """A finding whose message starts with its file and row (``states.parquet: row 40: ...``) is
    printed with its location once (text report and HTML table)."""
    from helpers_common import small_recording

    rec = small_recording()
    xs = rec.states.column("x").to_numpy().copy()
    xs[40] += 30.0  # a 30 m jump in 0.1 s: kinematics.speed
    rec.states = rec.states.set_column(rec.states.column_names.index("x"), "x",
                                       __import__("pyarrow").array(xs))
    path = rec.write(tmp_path / "jump.aveas")
    code, out, _ = cli(capsys, "validate", path, "--select", "kinematics.speed")
    lines = [ln for ln in out.splitlines() if ln.startswith("ERROR   kinematics.speed ")]
    assert code == 1 and lines, out
    for ln in lines:
        assert ln.count("states.parquet") == 1 and ln.count("row") == 1 and "table=" not in ln, ln
        assert re.search(r"states\.parquet row=\d+ participant_id=\d+ time=[\d.]+ column=x,y: "
                         r"participant \d+ \(car\) moves at", ln), ln
    cli(capsys, "validate", path, "--select", "kinematics.speed", "--format", "html", "-o",
        tmp_path / "r.html")
    html_text = (tmp_path / "r.html").read_text()
    assert "<td>states.parquet</td>" in html_text and "<td>states.parquet: row" not in html_text


def test_messages_cite_the_format_doc_users_have(capsys, env, tmp_path):
    from aveas_format.validate.registry import load_rules

    cited = [r.enforces for r in load_rules().values() if r.enforces]
    assert cited and not [c for c in cited if "FORMAT.md" in c]
    assert sum(c.startswith("docs/format.md §") for c in cited) > 30
    cli(capsys, "validate", env["REC"], "--format", "html", "-o", tmp_path / "r.html")
    page = (tmp_path / "r.html").read_text()
    assert "FORMAT.md" not in page and "docs/format.md §" in page


def test_map_commands_take_a_recording_and_say_no_points(capsys, env, tmp_path):
    code, out, err = cli(capsys, "map", "project", env["REC"], "--points", env["PTS"])
    assert code == 0 and out.splitlines()[1].startswith("10,-1.75,\"1\",-1,10,"), (out, err)
    zipped = env["REC"].parent / "rec.aveas.zip"
    if not zipped.exists():
        import aveas_format

        aveas_format.open(env["REC"]).write(zipped)
    code, out, _ = cli(capsys, "map", "info", zipped, "--format", "json")
    assert code == 0 and json.loads(out)["path"] == f"{zipped}/map.xodr"
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = cli(capsys, "map", "check", empty)
    assert code == 3 and "neither an OpenDRIVE map nor a recording" in one_error_line(err)
    header_only = tmp_path / "h.csv"
    header_only.write_text("x,y,heading\n")
    code, _, err = cli(capsys, "map", "project", env["MAP"], "--points", header_only)
    assert code == 3 and f"{header_only}: no points in the file" in one_error_line(err)


def test_dir_lists_the_lazy_api():
    import aveas_format

    assert {"open", "validate", "Recording", "build_recording"} <= set(dir(aveas_format))
    code = ("import sys, aveas_format; dir(aveas_format); "
            "print('pyarrow' in sys.modules, 'aveas_format.io.reader' in sys.modules)")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.stdout.split() == ["False", "False"], res  # the lazy loading is kept


# ---------------------------------------------------------------------------------------------
# exports of one recording, side by side, and their re-imports
@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """The demo's scene, smaller: 25 Hz, 0.1 m position noise, a 0.4 s sensor outage."""
    from aveas_format.sample import highway_scene

    return highway_scene(n_vehicles=12, duration_s=12.0, rate_hz=25.0).write(
        tmp_path_factory.mktemp("scene") / "hw.aveas")


def test_exports_side_by_side_re_import_with_nothing_asked(capsys, scene, tmp_path):
    """Issue 42's second hour, as a user would: exports of one recording next to each other share
    their map (no refusal), each re-imports without --map or -O (the map's name and the metadata
    travel in the file; a .osi trace has no place for the licence: one warning), the OpenSCENARIO
    round trip validates (no acceleration errors, no unexplained gaps), and the Foxglove MCAP says
    it is a viewing format."""
    import aveas_format

    for to, name in (("openlabel", "hw.json"), ("openscenario", "hw.xosc"), ("osi", "hw.osi"),
                     ("osi", "trace.mcap"), ("mcap", "hw.mcap")):
        code, _, err = cli(capsys, "export", "--to", to, scene, "-o", tmp_path / name)
        assert code == 0, err
    assert sorted(p.name for p in tmp_path.glob("*.xodr")) == ["hw.xodr", "trace.xodr"]
    src = aveas_format.open(scene).meta
    for name, conv, asked in (("hw.json", "openlabel", False), ("hw.xosc", "openscenario", False),
                              ("trace.mcap", "osi", False), ("hw.osi", "osi", True)):
        out = tmp_path / f"{name}.aveas"
        code, _, err = cli(capsys, "convert", "--from", conv, tmp_path / name, "-o", out)
        assert code == 0, f"{name}: {err}"
        assert ("does not state the licence" in err) == asked, err
        meta = aveas_format.open(out).meta
        assert meta.acquisition.partner == src.acquisition.partner or asked, name
        assert meta.rights.license == (src.rights.license if not asked else "unspecified"), name
        if conv == "openscenario":
            rep = aveas_format.validate(out)
            assert rep.counts["error"] == 0
            assert not {f.code for f in rep.findings()} & {"time.gap", "kinematics.acceleration",
                                                            "time.nominal_rate_low"}
            assert meta.start_time == src.start_time and meta.nominal_rate_hz == 10.0
    code, _, err = cli(capsys, "convert", "--from", "osi", tmp_path / "hw.mcap", "-o", tmp_path / "v")
    assert code == 3 and "a Foxglove MCAP for viewing" in one_error_line(err)
    code, _, err = cli(capsys, "validate", tmp_path / "hw.mcap")
    assert code == 3 and "a Foxglove MCAP for viewing" in one_error_line(err)
