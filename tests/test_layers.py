"""The package holds the layers of docs/architecture.md (the table lives in tools/layers.py)."""

from __future__ import annotations

import layers


def test_every_unit_is_in_a_layer():
    units = {p.stem if p.is_file() else p.name for p in layers.PACKAGE.iterdir()
             if (p.suffix == ".py" or (p / "__init__.py").exists())}
    assert units - set(layers.layer_of()) == set(), "add the new unit to tools/layers.py LAYERS"


def test_imports_follow_the_layers():
    assert layers.violations() == []


def test_the_check_catches_an_upward_import():
    bad = [layers.Edge("aveas_format.io.reader", "aveas_format.validate.report", 3),
           layers.Edge("aveas_format.sim.runner", "aveas_format", 7),
           layers.Edge("aveas_format.derive.traffic", "aveas_format.converters.common", 9)]
    found = layers.violations(bad)
    assert len(found) == 3
    assert "up: io is in layer 'storage, map engine', validate in 'domain'" in found[0]
    assert "package root" in found[1]
    assert "sideways" in found[2]


def test_no_import_cycles():
    """No module imports (directly or through others) one that imports it, and no unit (a
    subpackage or top-level module) does; what runs counts (lazy imports too, not those under
    ``if TYPE_CHECKING:``). Parts whose owners change them on their own branches are listed in
    tools/layers.py TOLERATED with the reason."""
    assert layers.cycle_violations() == []


def test_no_private_names_across_modules():
    """A name with a leading underscore stays inside its module: ``from M import _name`` and
    ``M._name`` elsewhere are refused (a subpackage gives its modules public names instead); a
    private module (``_protowire``) may be imported within its package."""
    assert layers.private_violations() == []


def test_the_checks_catch_a_cycle_and_a_private_name():
    g = {"aveas_format.io.reader": {"aveas_format.io.writer"},
         "aveas_format.io.writer": {"aveas_format.io.container"},
         "aveas_format.io.container": {"aveas_format.io.reader"},
         "aveas_format.converters.openlabel.read": {"aveas_format.converters.openlabel.parts"},
         "aveas_format.converters.openlabel.parts": {"aveas_format.converters.openlabel.read"}}
    assert layers.cycle_violations(g) == [
        "import cycle between modules: aveas_format.converters.openlabel.parts <-> "
        "aveas_format.converters.openlabel.read",
        "import cycle between modules: aveas_format.io.container <-> aveas_format.io.reader <-> "
        "aveas_format.io.writer"]
    uses = [layers.PrivateUse("aveas_format.converters.osi", "aveas_format.converters.osi_columns",
                              "_sub", 12),
            layers.PrivateUse("aveas_format.converters.openlabel.read",
                              "aveas_format.converters.openlabel.decode", "_pose", 3)]
    assert layers.private_violations(uses) == [
        "aveas_format.converters.osi:12: uses aveas_format.converters.osi_columns._sub",
        "aveas_format.converters.openlabel.read:3: uses aveas_format.converters.openlabel.decode._pose"]


def test_private_uses_are_read_from_the_code(tmp_path):
    pkg = tmp_path / "aveas_format"
    (pkg / "sub").mkdir(parents=True)
    for f in ("__init__.py", "sub/__init__.py", "sub/_helper.py"):
        (pkg / f).write_text("")
    (pkg / "sub" / "a.py").write_text("def _f():\n    pass\n")
    (pkg / "sub" / "b.py").write_text("from aveas_format.sub.a import _f\n"
                                      "from aveas_format.sub import _helper\n"
                                      "from aveas_format.sub import a as m\n"
                                      "x = m._f\n")
    (pkg / "c.py").write_text("from aveas_format.sub import _helper\n")
    found = {(u.module, u.name) for u in layers.private_uses(pkg)}
    assert found == {("aveas_format.sub.b", "_f"), ("aveas_format.c", "_helper")}


def test_exceptions_are_still_needed():
    """An exception nobody uses any more is removed from the table."""
    edges = {(e.module, e.dst_unit) for e in layers.imports()}
    assert set(layers.EXCEPTIONS) <= edges
    used = {(e.src_unit, e.dst_unit) for e in layers.imports()}
    assert set(layers.SIDEWAYS) <= used


def test_architecture_doc_shows_the_generated_picture_and_table():
    doc = (layers.PACKAGE.parent / "docs" / "architecture.md").read_text(encoding="utf-8")
    assert "figures/architecture_layers.png" in doc
    assert (layers.PACKAGE.parent / "docs" / "figures" / "architecture_layers.png").stat().st_size > 10_000
    assert layers.markdown_table() in doc  # tests/test_docs.py also checks it is current
