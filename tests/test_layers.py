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
