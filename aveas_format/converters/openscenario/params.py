"""OpenSCENARIO parameters, expressions and catalogs: what the import resolves before it replays.

- ``ParameterDeclarations`` at every level (scenario, story, act, trajectory, catalog entry...) are
  lexically scoped: :func:`resolve_tree` walks the document once, keeps a scope per element that
  declares parameters and replaces every attribute ``$name`` by its value. The scenario's own
  declarations can be overridden (``-O parameter.NAME=VALUE``).
- Expressions ``${...}`` (OpenSCENARIO 1.1+): numbers, ``$name`` references, ``+ - * / %``,
  unary minus, ``**`` is *not* allowed (the standard has ``pow``), parentheses, comparisons,
  ``and``/``or``/``not``, ``true``/``false``, and the standard's functions ``round floor ceil sqrt
  pow sin cos tan asin acos atan abs min max``; ``pi`` (an esmini extension, used in its files).
  They are evaluated on a parsed syntax tree with a whitelist (no ``eval``): anything else is an
  error naming the XML line. Results are floats (booleans ``true``/``false``).
- ``CatalogReference``: the entry named ``entryName`` of the catalog ``catalogName`` found in the
  ``CatalogLocations`` directories (relative to the scenario file), copied and resolved with its own
  ``ParameterDeclarations`` overridden by the reference's ``ParameterAssignments``.

Parameter variation files (``ParameterValueDistribution``) are expanded by :mod:`.variation`
into the values of one concrete variation. Not resolved: ``ParameterSetAction``
/ ``ParameterModifyAction`` at run time (the replay keeps the declared values), ``VariableDeclarations``.
"""

from __future__ import annotations

import ast
import copy
import math
import operator
import re
from pathlib import Path
from typing import Any

from lxml import etree

from aveas_format.errors import FormatError, did_you_mean

_BIN = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul,
        ast.Div: operator.truediv, ast.Mod: math.fmod}
_CMP = {ast.Lt: operator.lt, ast.LtE: operator.le, ast.Gt: operator.gt, ast.GtE: operator.ge,
        ast.Eq: operator.eq, ast.NotEq: operator.ne}
_FUN = {"round": lambda v: float(math.floor(v + 0.5)), "floor": math.floor, "ceil": math.ceil,
        "sqrt": math.sqrt, "pow": math.pow, "sin": math.sin, "cos": math.cos, "tan": math.tan,
        "asin": math.asin, "acos": math.acos, "atan": math.atan, "abs": abs, "min": min, "max": max}
#: the number of arguments of each function: (at least, at most)
_ARITY = {name: (1, 1) for name in _FUN} | {"pow": (2, 2), "min": (1, 99), "max": (1, 99)}
_CONST = {"pi": math.pi, "true": 1.0, "false": 0.0}
#: operators the expressions do not have, by how a user writes them (``**``: the standard has pow)
_OP_TEXT = {ast.Pow: "**", ast.FloorDiv: "//", ast.MatMult: "@", ast.BitAnd: "&", ast.BitOr: "|",
            ast.BitXor: "^", ast.LShift: "<<", ast.RShift: ">>", ast.Invert: "~", ast.Is: "is",
            ast.IsNot: "is not", ast.In: "in", ast.NotIn: "not in"}
_ALLOWED = ("numbers, $parameters, + - * / %, unary -, comparisons, and/or/not (&& || !), "
            "parentheses, the constants pi, true, false and the functions " + ", ".join(sorted(_FUN)))
_REF = re.compile(r"\$([A-Za-z_][A-Za-z0-9_]*)")
_MAX_EXPR = 1000


def _num(v: Any) -> float:
    if isinstance(v, bool):
        return 1.0 if v else 0.0
    if isinstance(v, (int, float)):
        return float(v)
    s = str(v).strip().lower()
    if s in ("true", "false"):
        return 1.0 if s == "true" else 0.0
    return float(s)


def _piece(n: ast.AST) -> str:
    """The part of the expression ``n`` stands for, as text (never the syntax tree's repr)."""
    try:
        return ast.unparse(n)
    except (ValueError, TypeError, AttributeError, RecursionError):  # pragma: no cover - unparse of a parsed tree
        return "part of the expression"


def evaluate(expr: str, scope: dict[str, str], line: int | None = None) -> float:
    """The value of an OpenSCENARIO expression (the text inside ``${...}``).

    Every rejected expression is a :class:`~aveas_format.errors.FormatError` naming the XML
    ``line`` and what is wrong in the user's words: an unknown function or name (with the closest
    allowed one and the list of what is allowed), an operator the standard does not have (``**``:
    use ``pow``), text that does not parse, a division by zero, a function outside its domain.
    """
    def fail(what: str) -> FormatError:
        return FormatError(f"expression ${{{expr}}}: {what}", line=line)

    if len(expr) > _MAX_EXPR:
        raise FormatError(f"expression longer than {_MAX_EXPR} characters", line=line)

    def ref(m: re.Match) -> str:
        name = m.group(1)
        if name not in scope:
            raise fail(f"parameter ${name} is not declared")
        try:
            value = _num(scope[name])
        except ValueError:
            raise fail(f"parameter ${name} = {scope[name]!r} is not a number") from None
        if not math.isfinite(value):
            raise fail(f"parameter ${name} = {scope[name]!r} is not a finite number")
        return f"({value!r})"

    text = _REF.sub(ref, expr).replace("&&", " and ").replace("||", " or ").replace("!=", "≠")
    text = text.replace("!", " not ").replace("≠", "!=")
    if not text.strip():
        raise fail("the expression is empty")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as e:
        raise fail(f"cannot be parsed ({e.msg}); allowed: {_ALLOWED}") from None
    except (ValueError, RecursionError):  # null bytes, absurd nesting
        raise fail(f"cannot be parsed; allowed: {_ALLOWED}") from None

    def call(n: ast.Call) -> float:
        if not isinstance(n.func, ast.Name):
            raise fail(f"{_piece(n.func)!r} is not a function; allowed: {', '.join(sorted(_FUN))}")
        name = n.func.id
        if name not in _FUN:
            raise fail(f"unknown function {name!r}{did_you_mean(name, _FUN)}; allowed: "
                       f"{', '.join(sorted(_FUN))}")
        if n.keywords or any(isinstance(a, ast.Starred) for a in n.args):
            raise fail(f"{name}() takes plain arguments, not {_piece(n)!r}")
        lo, hi = _ARITY[name]
        if not lo <= len(n.args) <= hi:
            want = f"{lo}" if lo == hi else f"at least {lo}"
            raise fail(f"{name}() takes {want} argument{'s' if hi > 1 else ''}, not {len(n.args)}")
        args = [ev(a) for a in n.args]
        try:
            return float(_FUN[name](*args))
        except ValueError:
            shown = ", ".join(_fmt(a) for a in args)
            raise fail(f"{name}({shown}) is undefined (outside the function's domain)") from None
        except OverflowError:
            raise fail(f"{name}() overflows (the result is too large)") from None

    def ev(n: ast.AST) -> float:
        if isinstance(n, ast.Expression):
            return ev(n.body)
        if isinstance(n, ast.Constant):
            if isinstance(n.value, (int, float)) and not isinstance(n.value, bool):
                return float(n.value)
            raise fail(f"{_piece(n)} is not a number")
        if isinstance(n, ast.Name):
            if n.id.lower() in _CONST:
                return _CONST[n.id.lower()]
            known = list(_CONST) + list(scope)
            raise fail(f"unknown name {n.id!r}{did_you_mean(n.id, known)} (a parameter is written "
                       f"${n.id}; constants: pi, true, false)")
        if isinstance(n, ast.BinOp):
            if type(n.op) not in _BIN:
                hint = " (use pow(x, y))" if isinstance(n.op, ast.Pow) else ""
                raise fail(f"operator {_OP_TEXT.get(type(n.op), '?')!r} is not allowed{hint}; allowed: {_ALLOWED}")
            left, right = ev(n.left), ev(n.right)
            if right == 0 and isinstance(n.op, (ast.Div, ast.Mod)):
                values = " (the parameters replaced by their values)" if "$" in expr else ""
                raise fail(f"division by zero in {_piece(n)!r}{values}")
            try:
                return float(_BIN[type(n.op)](left, right))
            except OverflowError:
                raise fail(f"{_piece(n)!r} overflows (the result is too large)") from None
        if isinstance(n, ast.UnaryOp):
            if isinstance(n.op, (ast.USub, ast.UAdd)):
                v = ev(n.operand)
                return -v if isinstance(n.op, ast.USub) else v
            if isinstance(n.op, ast.Not):
                return 0.0 if ev(n.operand) else 1.0
            raise fail(f"operator {_OP_TEXT.get(type(n.op), '?')!r} is not allowed; allowed: {_ALLOWED}")
        if isinstance(n, ast.BoolOp):
            vals = [bool(ev(v)) for v in n.values]
            return float(all(vals) if isinstance(n.op, ast.And) else any(vals))
        if isinstance(n, ast.Compare):
            bad = [o for o in n.ops if type(o) not in _CMP]
            if bad:
                raise fail(f"operator {_OP_TEXT.get(type(bad[0]), '?')!r} is not allowed; allowed: {_ALLOWED}")
            left = ev(n.left)
            for op, right in zip(n.ops, n.comparators):
                r = ev(right)
                if not _CMP[type(op)](left, r):
                    return 0.0
                left = r
            return 1.0
        if isinstance(n, ast.Call):
            return call(n)
        raise fail(f"{_piece(n)!r} is not allowed; allowed: {_ALLOWED}")

    try:
        value = ev(tree)
    except RecursionError:
        raise fail("nested too deeply") from None
    if not math.isfinite(value):
        raise fail(f"the result {value} is not a finite number")
    return value


def _fmt(v: float) -> str:
    return str(int(v)) if float(v).is_integer() and abs(v) < 1e15 else repr(float(v))


def value_of(raw: str, scope: dict[str, str], line: int | None = None) -> str:
    """An attribute value with its parameter reference or expression resolved."""
    if not raw or "$" not in raw:
        return raw
    s = raw.strip()
    if s.startswith("${") and s.endswith("}"):
        return _fmt(evaluate(s[2:-1], scope, line))
    if s.startswith("$"):
        name = s[1:]
        if name not in scope:
            raise FormatError(f"parameter reference {s!r} names no declared parameter", line=line)
        return scope[name]
    return raw


def declare(decls, scope: dict[str, str], overrides: dict[str, Any] | None = None) -> dict[str, str]:
    """``scope`` extended by the ``ParameterDeclaration`` children of ``decls`` (each evaluated in
    the scope so far; ``overrides`` win)."""
    out = dict(scope)
    if decls is None:
        return out
    for d in decls.iterfind("ParameterDeclaration"):
        name = d.get("name")
        if not name:
            continue
        if overrides and name in overrides:
            out[name] = str(overrides[name]).lower() if isinstance(overrides[name], bool) else str(overrides[name])
        else:
            out[name] = value_of(d.get("value", ""), out, d.sourceline)
    return out


def resolve_tree(el, scope: dict[str, str], overrides: dict[str, Any] | None = None) -> None:
    """Replace every ``$name`` / ``${expr}`` attribute under ``el`` (in place), with the lexical
    scoping of ``ParameterDeclarations``; ``overrides`` apply to the declarations directly under
    ``el`` (the scenario's global parameters)."""
    decls = el.find("ParameterDeclarations")
    if decls is not None:
        scope = declare(decls, scope, overrides)
    for k, v in el.attrib.items():
        if "$" in v:
            el.set(k, value_of(v, scope, el.sourceline))
    for child in el:
        if not isinstance(child.tag, str) or child.tag in ("ParameterDeclarations", "Catalog"):
            continue
        resolve_tree(child, scope)


class Catalogs:
    """The catalog entries reachable through a scenario's ``CatalogLocations``."""

    def __init__(self, root, base: Path, scope: dict[str, str]) -> None:
        from aveas_format.safeio import xml_parser

        self.entries: dict[tuple[str, str], Any] = {}
        self.scope = scope
        self.files: list[Path] = []
        #: applied to each resolved entry (the frame of a left-handed file: handedness.mirror)
        self.mirror: Any = None
        for loc in root.iterfind("CatalogLocations/*/Directory"):
            d = (base / (loc.get("path") or "")).resolve()
            if not d.is_dir():
                continue
            for f in sorted(d.glob("*.xosc")):
                try:
                    cat = etree.parse(str(f), xml_parser()).getroot().find("Catalog")
                except (OSError, etree.XMLSyntaxError) as e:
                    raise FormatError(f"catalog unreadable: {e}", path=f) from None
                if cat is None:
                    continue
                self.files.append(f)
                for entry in cat:
                    if isinstance(entry.tag, str) and entry.get("name"):
                        self.entries.setdefault((cat.get("name", ""), entry.get("name")), entry)

    def resolve(self, ref) -> Any:
        """A resolved copy of the entry a ``CatalogReference`` names; FormatError where none."""
        key = (ref.get("catalogName", ""), ref.get("entryName", ""))
        entry = self.entries.get(key)
        if entry is None:
            raise FormatError(f"catalog entry {key[1]!r} of catalog {key[0]!r} not found in the "
                              "CatalogLocations", line=ref.sourceline)
        entry = copy.deepcopy(entry)
        assigned = {a.get("parameterRef"): a.get("value") for a in
                    ref.iterfind("ParameterAssignments/ParameterAssignment")}
        resolve_tree(entry, dict(self.scope), assigned)
        if self.mirror is not None:
            self.mirror(entry)
        return entry
