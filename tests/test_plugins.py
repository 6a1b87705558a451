"""Plugins: one loader for converters, rules, derivations and commands, built-in or entry points.

The partner packages live in ``tests/plugins/``; a test makes one discoverable by writing its
``NAME-1.0.dist-info`` (METADATA + entry_points.txt) into a temporary directory on ``sys.path`` (or
``PYTHONPATH`` for the CLI), which is how an installed distribution is found by
``importlib.metadata``. In-process tests remove what the plugin registered afterwards.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from aveas_format import plugins
from aveas_format.converters.registry import CONVERTERS, convert, load_converters
from aveas_format.derive.registry import REGISTRY as DERIVATIONS
from aveas_format.derive.registry import derivations, derive
from aveas_format.errors import PluginError
from aveas_format.io.reader import open_recording
from aveas_format.opendrive.builder import straight_highway
from aveas_format.schema.tables import TABLES, derived_tables
from aveas_format.validate.registry import REGISTRY as RULES
from aveas_format.validate.registry import load_rules
from aveas_format.validate.runner import validate

PLUGINS = Path(__file__).resolve().parent / "plugins"
PARTNER = {
    "aveas_format.converters": {"partner-csv": "aveas_partner_plugin.converter"},
    "aveas_format.rules": {"partner": "aveas_partner_plugin.rules"},
    "aveas_format.derivations": {"partner_speed": "aveas_partner_plugin.derivation"},
    "aveas_format.commands": {"partner-hello": "aveas_partner_plugin.command"},
}
_PLUGIN_PACKAGES = ("aveas_partner_plugin", "aveas_broken_plugin", "aveas_duplicate_plugin")


def dist_info(site: Path, name: str, groups: dict[str, dict[str, str]]) -> Path:
    """Make the distribution ``name`` (version 1.0) with these entry points findable in ``site``."""
    d = site / f"{name.replace('-', '_')}-1.0.dist-info"
    d.mkdir(parents=True)
    (d / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    (d / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n"
        for group, eps in groups.items()))
    return site


@pytest.fixture
def install(tmp_path, monkeypatch):
    """``install(name, groups)`` makes a distribution's entry points visible to this process;
    everything its plugins register is removed again afterwards."""
    for kind in ("converters", "rules", "derivations"):
        plugins.load(kind)
    saved = (dict(CONVERTERS), dict(RULES), dict(DERIVATIONS))
    site = tmp_path / "site"
    monkeypatch.syspath_prepend(str(PLUGINS))
    monkeypatch.syspath_prepend(str(site))

    def install(name: str, groups: dict[str, dict[str, str]]) -> None:
        dist_info(site, name, groups)
        importlib.invalidate_caches()
        plugins.forget()

    yield install
    for name in set(DERIVATIONS) - set(saved[2]):
        if DERIVATIONS[name].spec is not None:
            TABLES.unregister(DERIVATIONS[name].table)
    for registry, before in zip((CONVERTERS, RULES, DERIVATIONS), saved):
        registry.clear()
        registry.update(before)
    for mod in [m for m in sys.modules if m.split(".")[0] in _PLUGIN_PACKAGES]:
        del sys.modules[mod]
    plugins.forget()


def cli(site: Path, *args: object) -> subprocess.CompletedProcess:
    """``aveas-format ARGS`` in a fresh process that sees the distributions in ``site``."""
    path = os.pathsep.join(filter(None, [str(PLUGINS), str(site), os.environ.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "aveas_format", *map(str, args)],
                          capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": path})


@pytest.fixture(scope="module")
def highway(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("maps") / "highway.xodr"
    p.write_text(straight_highway(length=500.0, lanes_right=2, geo_reference="+proj=tmerc "
                                  "+lat_0=48.8 +lon_0=11.1 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 "
                                  "+units=m +no_defs"))
    return p


def partner_csv(path: Path, participants: int) -> Path:
    """Cars driving along the right lanes of ``highway`` at 20 m/s, 10 Hz for 4 s."""
    rows = ["id,time,x,y"]
    for i in range(participants):
        for k in range(41):
            x, y = 20.0 + 30 * i + 2.0 * k, -1.75 - 3.5 * (i % 2)
            rows.append(f"{10 + i},{k / 10:.1f},{x:.2f},{y}")
    path.write_text("\n".join(rows) + "\n")
    return path


# --- built-ins through the loader ---------------------------------------------------------------


def test_builtin_modules_are_found_by_walking_the_packages():
    assert "aveas_format.converters.sumo_fcd" in plugins.import_tree("aveas_format.converters",
                                                                     skip=("registry", "common"))
    rules = plugins.import_tree("aveas_format.validate.rules")
    assert "aveas_format.validate.rules.structure" in rules and len(rules) == len(set(rules))
    assert {r.fn.__module__ for r in load_rules().values()} == set(rules)
    # streamed runs the derivations by time window; it registers none of its own
    assert {d.fn.__module__ for d in derivations().values()} == set(
        plugins.import_tree("aveas_format.derive", skip=("registry", "streamed")))


def test_a_subpackage_registers_exactly_once(tmp_path, monkeypatch):
    """Every module of a subpackage is imported once, whichever imports it first."""
    pkg = tmp_path / "demo_kind"
    (pkg / "nested").mkdir(parents=True)
    (pkg / "__init__.py").write_text("SEEN = []\n")
    (pkg / "helper.py").write_text("")
    (pkg / "_private.py").write_text("raise RuntimeError('never imported')\n")
    (pkg / "nested" / "__init__.py").write_text("from demo_kind.nested import reader  # noqa\n")
    (pkg / "nested" / "reader.py").write_text("import demo_kind\ndemo_kind.SEEN.append(__name__)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        names = plugins.import_tree("demo_kind", skip=("helper",))
        assert names == ["demo_kind.nested", "demo_kind.nested.reader"]
        assert plugins.import_tree("demo_kind", skip=("helper",)) == names
        assert sys.modules["demo_kind"].SEEN == ["demo_kind.nested.reader"]
    finally:
        for m in [m for m in sys.modules if m.split(".")[0] == "demo_kind"]:
            del sys.modules[m]


def test_derived_tables_are_declared_by_their_derivations():
    by_table = {d.table: d for d in derivations().values()}
    for spec in derived_tables():
        assert by_table[spec.name].spec is spec
        assert spec.file == f"{spec.name}.parquet" and spec.derived
    assert [s.name for s in derived_tables()] == sorted(s.name for s in derived_tables())
    with pytest.raises(ValueError, match="declared twice"):
        TABLES.register(TABLES["derived/kinematics"])
    with pytest.raises(KeyError):
        TABLES["derived/nothing"]


# --- a partner package ----------------------------------------------------------------------------


def test_partner_plugin_registers_a_converter_a_rule_and_a_derivation(install, highway, tmp_path):
    install("aveas-partner-plugin", PARTNER)
    conv = load_converters()["partner-csv"]
    assert conv.fn.__module__ == "aveas_partner_plugin.converter"
    r = load_rules()["partner.single_participant"]
    # the registry's own declaration checks hold for plugin rules as for built-in ones
    assert r.doc and r.title and r.message and r.severity.value == "info"
    assert "partner_speed" in derivations()
    assert TABLES["derived/partner_speed"].names == ("participant_id", "time", "speed", "speed_std")

    one = convert("partner-csv", [partner_csv(tmp_path / "one.csv", 1)], map_source=highway)
    two = convert("partner-csv", [partner_csv(tmp_path / "two.csv", 2)], map_source=highway)
    assert two.participants.column("source_id").to_pylist() == ["10", "11"]
    assert two.states.num_rows == 82 and two.meta.source.converter == "partner-csv"
    # the rule's failing and passing fixture
    assert validate(one, select=["partner"]).flatten(("code", "table")) == [
        ["partner.single_participant", "participants"]]
    assert validate(two, select=["partner"]).flatten(("code",)) == []

    assert derive(two, only="partner_speed") == ["partner_speed"]
    speed = two.derived["partner_speed"].column("speed").to_numpy()
    assert np.allclose(speed[1:-1], 20.0)
    path = two.write(tmp_path / "two.aveas")
    back = open_recording(path)
    assert back.derived["partner_speed"].num_rows == 82
    assert "derived/partner_speed" in json.loads((path / "recording.json").read_text())["tables"]
    report = validate(path)
    assert report.failures == [] and not any(c.startswith("structure.") for c in report.codes)


def test_a_partner_converter_takes_part_in_sniffing(install, highway, tmp_path):
    """The partner's ``sniff`` (its CSV header) picks it among every importer of ``*.csv``, so
    that ``aveas_format.validate(FILE)`` and ``aveas-format validate FILE`` take its files as
    they take the built-in formats; a CSV of another layout is not claimed by it."""
    from aveas_format.converters.registry import importers_for

    install("aveas-partner-plugin", PARTNER)
    one = partner_csv(tmp_path / "one.csv", 1)
    assert importers_for(one) == ["partner-csv"]
    other = tmp_path / "log.csv"
    other.write_text("time,id,x,y,heading,speed\n0,ego,20,-1.75,0,20\n")
    assert importers_for(other) == ["driving-simulator"]
    report = validate(one, map_source=highway, select=["partner"])
    assert report.recording == str(one)
    assert report.flatten(("code",)) == [["partner.single_participant"]]


def test_a_plugin_that_cannot_be_imported_is_one_clear_error(install):
    install("aveas-broken-plugin", {"aveas_format.rules": {"broken": "aveas_broken_plugin"}})
    with pytest.raises(PluginError) as e:
        load_rules()
    msg = str(e.value)
    assert msg == ("rules plugin 'broken' (aveas_broken_plugin) of aveas-broken-plugin 1.0 cannot "
                   "be loaded: ModuleNotFoundError: No module named "
                   "'aveas_partner_dependency_that_is_not_installed'")
    with pytest.raises(PluginError, match="rules plugin 'broken'"):  # never skipped later on
        load_rules()


@pytest.mark.parametrize("kind,module,both", [
    ("converters", "converter", ("aveas_duplicate_plugin.converter",
                                 "aveas_format.converters.sumo_fcd")),
    ("rules", "rule", ("'structure.checksum'", "aveas_format.validate.rules.structure")),
    ("derivations", "derivation", ("aveas_duplicate_plugin.derivation",
                                   "aveas_format.derive.kinematics")),
    ("derivations", "table", ("aveas_duplicate_plugin.table", "derived/kinematics",
                              "aveas_format.derive.kinematics")),
])
def test_a_plugin_cannot_register_a_name_that_exists(install, kind, module, both):
    install("aveas-duplicate-plugin",
            {f"aveas_format.{kind}": {"dup": f"aveas_duplicate_plugin.{module}"}})
    with pytest.raises(PluginError) as e:
        plugins.load(kind)
    msg = str(e.value)
    assert msg.startswith(f"{kind} plugin 'dup' (aveas_duplicate_plugin.{module}) of "
                          "aveas-duplicate-plugin 1.0 cannot be loaded: ValueError: ")
    assert all(name in msg for name in both) and "\n" not in msg, msg


# --- the command line -----------------------------------------------------------------------------


def test_cli_finds_the_partner_plugin(tmp_path, highway):
    site = dist_info(tmp_path / "site", "aveas-partner-plugin", PARTNER)
    res = cli(site, "convert", "--list")
    assert res.returncode == 0 and "partner-csv" in res.stdout, res.stderr
    out = tmp_path / "one.aveas"
    res = cli(site, "convert", "--from", "partner-csv", partner_csv(tmp_path / "one.csv", 1),
              "--map", highway, "-o", out, "-O", "partner=test", "-O", "license=CC-BY-4.0",
              "-O", "start_time=2024-05-13T08:15:00Z")
    assert res.returncode == 0, res.stderr
    res = cli(site, "validate", out, "--format", "json", "--select", "partner")
    report = json.loads(res.stdout)
    assert report["rules_run"] == ["partner.single_participant"]
    assert [r["code"] for r in report["results"]] == ["partner.single_participant"]
    res = cli(site, "validate", tmp_path / "one.csv", "--map", highway, "--format", "json",
              "--select", "partner")  # a partner file, its importer sniffed
    assert [r["code"] for r in json.loads(res.stdout)["results"]] == ["partner.single_participant"]
    res = cli(site, "derive", out, "--only", "partner_speed", "--in-place")
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["tables"] == {"derived/partner_speed": 41}
    res = cli(site, "partner-hello")
    assert (res.returncode, res.stdout) == (0, "hello from aveas_partner_plugin\n"), res.stderr


@pytest.mark.parametrize("group,args", [
    ("aveas_format.converters", ("convert", "--list")),
    ("aveas_format.commands", ("schema",)),
])
def test_cli_reports_a_broken_plugin_in_one_line(tmp_path, group, args):
    site = dist_info(tmp_path / "site", "aveas-broken-plugin",
                     {group: {"broken": "aveas_broken_plugin"}})
    res = cli(site, *args)
    kind = group.split(".")[1]
    assert res.returncode == 3, (res.stdout, res.stderr)
    assert res.stderr == (f"aveas-format: error: {kind} plugin 'broken' (aveas_broken_plugin) of "
                          "aveas-broken-plugin 1.0 cannot be loaded: ModuleNotFoundError: No module "
                          "named 'aveas_partner_dependency_that_is_not_installed'\n")


def test_cli_refuses_a_second_command_of_a_name(tmp_path):
    site = dist_info(tmp_path / "site", "aveas-duplicate-plugin",
                     {"aveas_format.commands": {"dup": "aveas_duplicate_plugin.command"}})
    res = cli(site, "info", "--help")
    assert res.returncode == 3 and len(res.stderr.splitlines()) == 1, res.stderr
    assert ("command 'info' of aveas_duplicate_plugin.command registered twice: "
            "aveas_format.cli.info has it") in res.stderr


def test_entry_point_groups_are_the_documented_ones():
    assert {k.group for k in plugins.KINDS.values()} == {
        "aveas_format.converters", "aveas_format.rules", "aveas_format.derivations",
        "aveas_format.commands"}
    text = (Path(__file__).resolve().parent.parent / "docs" / "extending.md").read_text()
    assert all(f'"{k.group}"' in text for k in plugins.KINDS.values())


def test_io_loads_the_derivations_only_when_it_meets_a_derived_table(written, tmp_path):
    """The derived specs are declared by the derivations: reading core tables imports no derive."""
    code = ("import sys; from aveas_format.io.reader import open_recording; "
            "rec = open_recording(sys.argv[1]); "
            "print(sorted(rec.derived), "
            "any(m.startswith('aveas_format.derive') for m in sys.modules))")

    def run(path: Path) -> str:
        return subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                              text=True, check=True).stdout.strip()

    assert run(written) == "[] False"
    rec = open_recording(written)
    derive(rec, only="kinematics")
    assert run(rec.write(tmp_path / "derived.aveas")) == "['kinematics'] True"
