"""The environment a tutorial runs in: what ``pip install -e ".[demo]"`` (``make demo``) installs,
not the development venv with every extra (a repository tool, used by :mod:`docgen`).

:func:`extras_closure` resolves the distributions of the core install plus some extras (the
project's own requirements from ``pyproject.toml``, the rest from the installed packages'
metadata); :func:`blocked_modules` lists the top-level modules installed here that such an
install would not have. :class:`PythonRunner` runs a tutorial's Python blocks in a separate
interpreter in which those modules cannot be imported (``No module named 'pandas'``, as in the
demo's venv), and :func:`env_with_blocker` gives the shell commands the same restriction (a
``sitecustomize`` on ``PYTHONPATH``). A block runs in a fresh namespace unless its first line says
it continues the block above (``# continues the block above: rec``), so that a reader who copies
one block knows what it needs.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parent.parent
PROJECT = "aveas-format"

#: a Python block whose first line says so keeps the namespace of the block before it
CONTINUES = re.compile(r"\A\s*#[^\n]*\bcontinues\b", re.IGNORECASE)

#: the import blocker: refuses the listed top-level modules the way a missing package does
_BLOCKER = '''
import json as _json, os as _os, sys as _sys


class _NotInstalled:
    """Top-level modules this install would not have (tools/tutorial_env.py)."""

    def __init__(self, names):
        self.names = frozenset(names)

    def find_spec(self, name, path=None, target=None):
        if name.partition(".")[0] in self.names:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None


_names = _json.loads(_os.environ.get("AVEAS_TUTORIAL_BLOCKED", "[]"))
if _names:
    import importlib.util as _util

    _blocker = _NotInstalled(_names)
    _sys.meta_path.insert(0, _blocker)
    _find_spec = _util.find_spec

    def _find_spec_unless_blocked(name, package=None):
        """``importlib.util.find_spec`` answers None for a module that is not installed."""
        absolute = _util.resolve_name(name, package) if name.startswith(".") else name
        if absolute.partition(".")[0] in _blocker.names:
            return None
        return _find_spec(name, package)

    _util.find_spec = _find_spec_unless_blocked
'''

#: the Python worker: reads ``{"file", "where", "fresh"}`` lines, runs each file's code, answers
#: ``@@ok`` or ``@@error {json}`` on its own line (block output goes to stderr)
_WORKER = '''
import contextlib, json, sys, traceback
ns = {"__name__": "__tutorial__"}
for line in sys.stdin:
    job = json.loads(line)
    if job["fresh"]:
        ns = {"__name__": "__tutorial__"}
    code = open(job["file"], encoding="utf-8").read()
    try:
        with contextlib.redirect_stdout(sys.stderr):
            exec(compile(code, job["where"], "exec"), ns)
    except BaseException as e:  # noqa: BLE001 - reported to the runner
        hint = ""
        if isinstance(e, NameError):
            hint = (" (a block runs on its own: one that uses an earlier block's names starts "
                    "with a comment saying it continues the block above)")
        print("@@error " + json.dumps(f"{type(e).__name__}: {e}{hint}"), flush=True)
        continue
    print("@@ok", flush=True)
'''


def _project() -> tuple[list[str], dict[str, list[str]]]:
    """The project's core requirements and extras, from this checkout's pyproject.toml."""
    data = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    return list(data.get("dependencies", [])), dict(data.get("optional-dependencies", {}))


def _requires(dist: str, extras: frozenset[str]) -> list[Requirement]:
    """The requirements of installed distribution ``dist`` with ``extras`` (markers applied)."""
    try:
        reqs = metadata.requires(dist) or []
    except metadata.PackageNotFoundError:
        return []
    out = []
    for text in reqs:
        req = Requirement(text)
        envs = [{"extra": e} for e in extras] or [{"extra": ""}]
        if req.marker is None or any(req.marker.evaluate(env) for env in envs):
            out.append(req)
    return out


def extras_closure(extras: tuple[str, ...] | list[str]) -> set[str]:
    """Canonical names of every distribution ``pip install aveas-format[EXTRAS]`` installs
    (the project itself included), resolved against what is installed here."""
    core, optional = _project()
    todo: list[Requirement] = [Requirement(r) for r in core]
    seen_extras: set[str] = set()
    pending = list(extras)
    while pending:  # the project's extras, which may name its other extras
        extra = pending.pop()
        if extra in seen_extras:
            continue
        seen_extras.add(extra)
        for text in optional.get(extra, []):
            req = Requirement(text)
            if canonicalize_name(req.name) == canonicalize_name(PROJECT):
                pending.extend(req.extras)
            else:
                todo.append(req)
    found = {canonicalize_name(PROJECT)}
    visited: set[tuple[str, frozenset[str]]] = set()
    while todo:
        req = todo.pop()
        key = (canonicalize_name(req.name), frozenset(req.extras))
        if key in visited:
            continue
        visited.add(key)
        found.add(key[0])
        todo.extend(_requires(req.name, key[1]))
    return found


def blocked_modules(extras: tuple[str, ...] | list[str]) -> list[str]:
    """Top-level modules installed here that ``pip install aveas-format[EXTRAS]`` would not have
    (the standard library is never blocked)."""
    keep = extras_closure(extras)
    out = []
    for module, dists in metadata.packages_distributions().items():
        if module in sys.stdlib_module_names or module.startswith("_") or module == "aveas_format":
            continue
        if not any(canonicalize_name(d) in keep for d in dists):
            out.append(module)
    return sorted(out)


def env_with_blocker(env: dict[str, str], blocked: list[str], where: Path) -> dict[str, str]:
    """``env`` for subprocesses in which ``blocked`` modules cannot be imported: a
    ``sitecustomize.py`` in ``where`` put first on ``PYTHONPATH``."""
    where.mkdir(parents=True, exist_ok=True)
    (where / "sitecustomize.py").write_text(_BLOCKER, encoding="utf-8")
    path = os.pathsep.join(p for p in (str(where), env.get("PYTHONPATH", "")) if p)
    return {**env, "PYTHONPATH": path, "AVEAS_TUTORIAL_BLOCKED": json.dumps(blocked)}


class PythonRunner:
    """A separate interpreter that runs Python blocks one after the other (``env`` decides what
    it can import); :meth:`run` returns None or the error of a block."""

    def __init__(self, env: dict[str, str], cwd: Path, scratch: Path) -> None:
        self.scratch = scratch
        scratch.mkdir(parents=True, exist_ok=True)
        self.log = open(scratch / "output.txt", "w", encoding="utf-8")  # the blocks' prints
        self.proc = subprocess.Popen([sys.executable, "-c", _WORKER], cwd=cwd, env=env, text=True,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self.log)
        self.count = 0

    def run(self, code: str, where: str) -> str | None:
        self.count += 1
        file = self.scratch / f"block{self.count}.py"
        file.write_text(code, encoding="utf-8")
        fresh = CONTINUES.match(code) is None
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps({"file": str(file), "where": where, "fresh": fresh}) + "\n")
        self.proc.stdin.flush()
        for line in self.proc.stdout:
            if line.startswith("@@ok"):
                return None
            if line.startswith("@@error "):
                return json.loads(line[len("@@error "):])
        return f"the Python process ended (exit {self.proc.wait()})"

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            self.proc.kill()
        self.log.close()
