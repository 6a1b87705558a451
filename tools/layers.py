"""The layers of the package, in one place, and its import graph read from the source.

``LAYERS`` lists the units of ``aveas_format`` (top-level modules and subpackages) from the bottom
up. A unit may import any unit of a lower layer; within a layer only the edges in ``SIDEWAYS`` are
allowed; ``EXCEPTIONS`` names the few module-level imports that go up, each with its reason.
``tests/test_layers.py`` checks the package against this table (lazy imports inside functions count
too) and ``tools/docgen.py`` draws ``docs/figures/architecture_layers.png`` and the table in
``docs/architecture.md`` from it, so the picture cannot drift from the code.
"""

from __future__ import annotations

import ast
import functools
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "aveas_format"

#: bottom to top: (layer name, units, what the layer is for)
LAYERS: list[tuple[str, tuple[str, ...], str]] = [
    ("base", ("errors", "_version"), "the exception hierarchy and the version (standard library only)"),
    ("foundation", ("safeio", "numeric", "crs", "parallel", "plugins"),
     "hardened readers and atomic writes, array helpers, CRS strings and the local frame, the "
     "task runner, the plugin loader"),
    ("schema", ("schema",), "pydantic models and the one declaration per column (no pyarrow)"),
    ("storage, map engine", ("io", "opendrive"),
     "recordings on disk <-> Arrow tables; the OpenDRIVE engine (neither imports the other)"),
    ("map-referencing", ("mapref",), "road coordinates, a recording from plain arrays"),
    ("domain", ("converters", "derive", "validate", "sample"),
     "foreign formats, derived tables, the validator, synthetic sample data"),
    ("presentation", ("plot",), "every figure (matplotlib) and the HTML report"),
    ("consumers", ("dataset", "sim", "fit"), "archives of recordings, the SUMO runner, the fitter"),
    ("public API", ("__init__",), "aveas_format.open / build_recording / validate, imported lazily"),
    ("interface", ("cli",), "the command line: one module per command"),
    ("entry point", ("__main__",), "python -m aveas_format"),
]

#: allowed imports between units of the same layer
SIDEWAYS: dict[tuple[str, str], str] = {
    ("validate", "derive"): "metadata.derived_stale compares derived tables with their inputs",
    ("fit", "sim"): "the fitter simulates through the SUMO runner",
    ("dataset", "converters"): "convert many sources at once",
    ("validate", "converters"): "a submitted file of any importable format is imported to be "
                                "validated (validate/submission.py)",
}

#: module -> unit imports that break the order, each with its reason (docs/architecture.md)
#: (not an import, so not listed here: ``plugins`` imports the packages of the converters, rules,
#: derivations and commands by name at run time; ``schema.tables`` asks it for the derivations,
#: which declare the derived tables, when it meets one it does not know yet)
EXCEPTIONS: dict[tuple[str, str], str] = {
    ("aveas_format.io.recording", "opendrive"):
        "Recording.map parses map.xodr on first use (lazy import inside the property)",
}


def layer_of() -> dict[str, int]:
    return {u: i for i, (_, units, _) in enumerate(LAYERS) for u in units}


@dataclass(frozen=True)
class Edge:
    module: str  # importing module, dotted
    target: str  # imported module, dotted
    line: int

    @property
    def src_unit(self) -> str:
        return unit(self.module)

    @property
    def dst_unit(self) -> str:
        return unit(self.target)


@functools.lru_cache(maxsize=None)
def _parsed(path: Path, mtime_ns: int) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def _tree(path: Path) -> ast.Module:
    """The syntax tree of a source file (parsed once per version of the file)."""
    return _parsed(path, path.stat().st_mtime_ns)


def unit(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _module_name(path: Path, package: Path = PACKAGE) -> str:
    rel = path.relative_to(package.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__" and len(parts) > 1:
        parts = parts[:-1]
        return ".".join(parts) if len(parts) > 1 else "aveas_format.__init__"
    return ".".join(parts)


def _package_of(path: Path, mod: str) -> str:
    """The package a module's relative imports are relative to."""
    pkg = mod.rsplit(".", 1)[0] if path.name != "__init__.py" else mod
    return "aveas_format" if pkg == "aveas_format.__init__" else pkg


def _from_target(node: ast.ImportFrom, pkg: str) -> str:
    """The module named by ``from ... import`` (relative imports resolved against ``pkg``)."""
    if node.level:
        base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))
    return node.module or ""


def imports(package: Path = PACKAGE) -> list[Edge]:
    """Every import of a package module by a package module (module level and inside functions)."""
    out: list[Edge] = []
    for path in sorted(package.rglob("*.py")):
        mod = _module_name(path)
        pkg = _package_of(path, mod)
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom):
                target = _from_target(node, pkg)
                if not target.startswith("aveas_format"):
                    continue
                names = [target] if node.module else [f"{target}.{a.name}" for a in node.names]
                if target == "aveas_format":  # ``from aveas_format import safeio``
                    names = [f"aveas_format.{a.name}" for a in node.names]
                out += [Edge(mod, n, node.lineno) for n in names]
            elif isinstance(node, ast.Import):
                out += [Edge(mod, a.name, node.lineno) for a in node.names
                        if a.name.startswith("aveas_format")]
    return out


def violations(edges: list[Edge] | None = None) -> list[str]:
    """Imports that break the layer order, as readable lines (empty when the package holds)."""
    level = layer_of()
    out = []
    for e in edges if edges is not None else imports():
        a, b = e.src_unit, e.dst_unit
        if a == b:
            continue
        if a not in level or b not in level:
            missing = a if a not in level else b
            out.append(f"{e.module}:{e.line}: unit {missing!r} is in no layer of tools/layers.py")
            continue
        if (e.module, b) in EXCEPTIONS:
            continue
        if b == "__init__" and e.target == "aveas_format" and level[a] < level[b]:
            out.append(f"{e.module}:{e.line}: imports the package root (import the module instead)")
            continue
        if level[b] < level[a] or (level[b] == level[a] and (a, b) in SIDEWAYS):
            continue
        how = "sideways" if level[a] == level[b] else "up"
        out.append(f"{e.module}:{e.line}: imports {e.target} ({how}: {a} is in layer "
                   f"{LAYERS[level[a]][0]!r}, {b} in {LAYERS[level[b]][0]!r})")
    return out


def _graph(pairs) -> dict[str, set[str]]:
    """node -> the nodes it imports, from ``(importer, imported)`` pairs (self-imports left out)."""
    g: dict[str, set[str]] = defaultdict(set)
    for a, b in pairs:
        if a != b:
            g[a].add(b)
    return g


def unit_graph(edges: list[Edge] | None = None) -> dict[str, set[str]]:
    """unit -> the units it imports (self-imports left out)."""
    return _graph((e.src_unit, e.dst_unit) for e in (edges if edges is not None else imports()))


def markdown_table(edges: list[Edge] | None = None) -> str:
    """The layers top down with what each unit imports (generated into docs/architecture.md)."""
    g = unit_graph(edges)
    lines = ["| layer | unit | imports (read from the code) |", "|---|---|---|"]
    for name, units, _ in reversed(LAYERS):
        for u in units:
            deps = ", ".join(f"`{d}`" for d in sorted(g.get(u, ()))) or "—"
            shown = "aveas_format/__init__" if u == "__init__" else u
            lines.append(f"| {name} | `{shown}` | {deps} |")
    return "\n".join(lines)


def reduced(g: dict[str, set[str]]) -> dict[str, set[str]]:
    """The transitive reduction: a -> b is kept only where no other path leads from a to b."""
    def reach(start: str, skip: tuple[str, str]) -> set[str]:
        seen, stack = set(), [start]
        while stack:
            u = stack.pop()
            for v in g.get(u, ()):
                if (u, v) != skip and v not in seen:
                    seen.add(v)
                    stack.append(v)
        return seen

    return {a: {b for b in bs if b not in reach(a, (a, b))} for a, bs in g.items()}


def figure(path: Path, edges: list[Edge] | None = None) -> Path:
    """Draw the layers as bands with one box per unit and an arrow per unit import that no chain of
    other imports implies (the transitive reduction; the full list is the table of the docs)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

    edges = edges if edges is not None else imports()
    exceptional = {(e.src_unit, e.dst_unit) for e in edges if (e.module, e.dst_unit) in EXCEPTIONS}
    g = reduced(unit_graph([e for e in edges if (e.module, e.dst_unit) not in EXCEPTIONS]))
    for a, b in exceptional:
        g.setdefault(a, set()).add(b)
    pos: dict[str, tuple[float, float]] = {}
    width = 11.0
    fig, ax = plt.subplots(figsize=(11, 9))
    for i, (name, units, _) in enumerate(LAYERS):
        y = i * 1.15
        ax.add_patch(FancyBboxPatch((-0.2, y - 0.42), width + 0.4, 0.84, boxstyle="round,pad=0.02",
                                    fc="#f2f4f7" if i % 2 else "#e6ebf2", ec="none", zorder=0))
        ax.text(-0.35, y, name, ha="right", va="center", fontsize=9, color="#444")
        step = width / (len(units) + 1)
        for k, u in enumerate(units):
            x = step * (k + 1)
            pos[u] = (x, y)
            label = "aveas_format" if u == "__init__" else u
            ax.text(x, y, label, ha="center", va="center", fontsize=9, zorder=3,
                    bbox=dict(boxstyle="round,pad=0.3", fc="white", ec="#3b6ea5"))
    for a, deps in g.items():
        for b in deps:
            if a not in pos or b not in pos:
                continue
            (x0, y0), (x1, y1) = pos[a], pos[b]
            same = y0 == y1
            odd = (a, b) in exceptional
            ax.add_patch(FancyArrowPatch((x0, y0 - 0.18 if not same else y0),
                                         (x1, y1 + 0.18 if not same else y1),
                                         arrowstyle="-|>", mutation_scale=8, lw=0.6,
                                         ls="--" if odd else "-",
                                         color="#c0392b" if same else "#7f8c8d", alpha=0.55,
                                         connectionstyle="arc3,rad=0.25" if same else "arc3,rad=0.05",
                                         zorder=1))
    ax.set_xlim(-2.4, width + 0.4)
    ax.set_ylim(-0.7, (len(LAYERS) - 1) * 1.15 + 0.7)
    ax.axis("off")
    ax.set_title("aveas_format: layers and the imports between units, read from the code\n"
                 "(an arrow where no chain of other imports implies it; red: within a layer, as "
                 "tools/layers.py allows; dashed: the lazy Recording.map)", fontsize=10)
    fig.tight_layout()
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    path.write_bytes(buf.getvalue())
    return path


# --- import cycles and private names ---------------------------------------------------------------

def modules(package: Path = PACKAGE) -> set[str]:
    """The dotted names of the package's modules (a package as its name)."""
    out = set()
    for path in package.rglob("*.py"):
        name = _module_name(path, package)
        out.add("aveas_format" if name == "aveas_format.__init__" else name)
    return out


def _package_trees(package: Path):
    """``(module, its package, its syntax tree)`` of every module of ``package``, in path order."""
    for path in sorted(package.rglob("*.py")):
        mod = _module_name(path, package)
        yield mod, _package_of(path, mod), _tree(path)


def _imports(tree: ast.AST, pkg: str):
    """``(node, target, alias)`` of every import in ``tree`` that may name a package module:
    ``from TARGET import alias.name`` (TARGET resolved against ``pkg``, within the package) and
    ``import alias.name`` (target None)."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            target = _from_target(node, pkg)
            if target.startswith("aveas_format"):
                for a in node.names:
                    yield node, target, a
        elif isinstance(node, ast.Import):
            for a in node.names:
                yield node, None, a


def runtime_imports(package: Path = PACKAGE) -> list[Edge]:
    """Every import of a package module that runs (module level and inside functions; not those
    under ``if TYPE_CHECKING:``), its target the imported module: ``from pkg import name`` is
    ``pkg.name`` where that is a module, else ``pkg``."""
    mods = modules(package)
    out: list[Edge] = []
    for mod, pkg, tree in _package_trees(package):
        src = "aveas_format" if mod == "aveas_format.__init__" else mod
        typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                       and getattr(node.test, "id", getattr(node.test, "attr", None)) == "TYPE_CHECKING"
                       for stmt in node.body for n in ast.walk(stmt)}
        for node, target, a in _imports(tree, pkg):
            if id(node) in typing_only:
                continue
            if target is None:
                if a.name in mods:
                    out.append(Edge(src, a.name, node.lineno))
            else:
                full = f"{target}.{a.name}"
                out.append(Edge(src, full if full in mods else target, node.lineno))
    return out


def module_graph(edges: list[Edge] | None = None) -> dict[str, set[str]]:
    """module -> the modules it imports (:func:`runtime_imports`)."""
    return _graph((e.module, e.target) for e in (edges if edges is not None
                                                 else runtime_imports()))


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted: every
    import cycle, as the set of nodes on it."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # iterative would be longer; the graphs are small (depth < 100)
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(g.get(v, ())):
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

    for v in sorted(set(g) | {w for ws in g.values() for w in ws}):
        if v not in index:
            visit(v)
    return sorted(out)


@dataclass(frozen=True)
class PrivateUse:
    module: str  # the module that uses the name
    owner: str   # the module that defines it
    name: str
    line: int

    def __str__(self) -> str:
        return f"{self.module}:{self.line}: uses {self.owner}.{self.name}"


def private_uses(package: Path = PACKAGE) -> list[PrivateUse]:
    """Names with a leading underscore used outside their module: ``from M import _name`` and
    ``M._name`` on an imported module ``M`` of the package. A private module (``_protowire``) may
    be imported within its own package."""
    mods = modules(package)
    out: list[PrivateUse] = []
    for mod, pkg, tree in _package_trees(package):
        aliases: dict[str, str] = {}  # local name -> package module
        for node, target, a in _imports(tree, pkg):
            if target is None:
                if a.name in mods and a.asname:
                    aliases[a.asname] = a.name
                continue
            full = f"{target}.{a.name}"
            if full in mods:
                aliases[a.asname or a.name] = full
                if a.name.startswith("_") and not mod.startswith(target + ".") and mod != target:
                    out.append(PrivateUse(mod, target, a.name, node.lineno))
            elif _private(a.name) and target != mod:
                out.append(PrivateUse(mod, target, a.name, node.lineno))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and _private(node.attr)
                    and aliases[node.value.id] != mod):
                out.append(PrivateUse(mod, aliases[node.value.id], node.attr, node.lineno))
    return out


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


#: package -> why import cycles or private names used across its modules are tolerated there
#: (tests/test_layers.py checks everything else; none is tolerated today: an entry needs a reason)
TOLERATED: dict[str, str] = {}
#: single private names used across modules outside those packages, each with its reason
TOLERATED_USES: dict[tuple[str, str, str], str] = {}


def tolerated(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in TOLERATED)


def cycle_violations(g: dict[str, set[str]] | None = None) -> list[str]:
    """Import cycles between modules, and between units, outside :data:`TOLERATED`."""
    out = [f"import cycle between modules: {' <-> '.join(c)}"
           for c in cycles(g if g is not None else module_graph())
           if not all(tolerated(m) for m in c)]
    out += [f"import cycle between units: {' <-> '.join(c)}"
            for c in cycles({k: set(v) for k, v in unit_graph().items()})] if g is None else []
    return out


def private_violations(uses: list[PrivateUse] | None = None) -> list[str]:
    """Private names used across modules outside :data:`TOLERATED` and :data:`TOLERATED_USES`."""
    return [str(u) for u in (uses if uses is not None else private_uses())
            if not tolerated(u.module) and (u.module, u.owner, u.name) not in TOLERATED_USES]
