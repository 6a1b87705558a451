"""The house of opendrive/ (issue 41): no import cycles between its modules, and no module imports
another's underscore names or reaches into another object's underscore attributes."""

from __future__ import annotations

import ast
from collections import defaultdict

import layers

PKG = "aveas_format.opendrive"


def _modules() -> set[str]:
    root = layers.PACKAGE / "opendrive"
    out = set()
    for p in root.rglob("*.py"):
        rel = p.relative_to(layers.PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.add(".".join(parts))
    return out


def _graph() -> dict[str, set[str]]:
    mods = _modules()
    g: dict[str, set[str]] = defaultdict(set)
    for e in layers.imports():
        if not e.module.startswith(PKG) or not e.target.startswith(PKG):
            continue
        target = e.target
        while target not in mods:  # ``from .x import name`` -> module x
            target = target.rsplit(".", 1)[0]
        if target != e.module:
            g[e.module].add(target)
    return g


def _cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(g):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles_in_opendrive():
    assert _cycles(_graph()) == []


def test_the_cycle_check_finds_a_cycle():
    g = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(g) == [["a", "b", "c"]]


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
