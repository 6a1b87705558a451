"""The house of opendrive/ beyond tests/test_layers.py (no import cycles, no underscore names
imported across modules, anywhere): here no module reaches into another object's underscore
attributes either."""

from __future__ import annotations

import ast

import layers


def test_no_underscore_names_across_opendrive_modules():
    bad = []
    for p in (layers.PACKAGE / "opendrive").rglob("*.py"):
        tree = ast.parse(p.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                bad += [f"{p.name}:{node.lineno} imports {a.name}" for a in node.names
                        if a.name.startswith("_") and not a.name.startswith("__")]
            elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
                owner = node.value
                if not (isinstance(owner, ast.Name) and owner.id in ("self", "cls")):
                    bad.append(f"{p.name}:{node.lineno} reads .{node.attr}")
    assert bad == []
