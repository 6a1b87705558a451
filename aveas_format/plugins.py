"""The plugin loader: one way to find the converters, rules, derivations and CLI commands.

Each of these *kinds* lives in modules that register themselves when they are imported, with the
decorator of their registry:

=============  ================================================  ===============================
kind           registers with                                    built-in package
=============  ================================================  ===============================
converters     ``@converter(...)`` (converters/registry.py)      ``aveas_format.converters``
rules          ``@rule(...)`` (validate/registry.py)             ``aveas_format.validate.rules``
derivations    ``register(Derivation(...))`` (derive/registry)   ``aveas_format.derive``
commands       ``@app.command()`` (cli/app.py)                   ``aveas_format.cli``
=============  ================================================  ===============================

:func:`load` imports, once per process, every module of the kind's built-in package (subpackages
included, each module once: a subpackage registers exactly once however its modules import each
other), then every module named by an entry point of the group ``aveas_format.<kind>`` of an
installed distribution (a partner package; docs/extending.md). Not imported: modules whose name
starts with ``_`` (private helpers, optional-dependency code) and the helper modules a kind declares
in :data:`KINDS` (its registry, shared code). The order is fixed: built-in modules by name, then
plugins by entry-point name.

A plugin that cannot be imported, or that registers a name that exists (the registries raise a
ValueError naming the module that holds the name), is a :class:`~aveas_format.errors.PluginError`:
one line naming the entry point and its distribution, never a traceback, never skipped; every later
:func:`load` of that kind raises it again.

Layers: this module imports only the standard library and :mod:`aveas_format.errors`. It names the
built-in packages as strings and imports them with :mod:`importlib`, the one documented way a lower
layer reaches a higher one at run time: ``schema.tables`` asks for the derivations (whose modules
declare the derived tables' specs) when it meets a derived table it does not know yet.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import pkgutil
from collections.abc import Iterable
from dataclasses import dataclass

from aveas_format.errors import PluginError


@dataclass(frozen=True)
class Kind:
    """What registers itself: its built-in package and the helper modules there that do not."""

    name: str
    package: str
    helpers: tuple[str, ...] = ()  # top-level modules of the package that register nothing

    @property
    def group(self) -> str:
        """The entry-point group of partner packages: ``aveas_format.<kind>``."""
        return f"aveas_format.{self.name}"


KINDS: dict[str, Kind] = {k.name: k for k in (
    Kind("converters", "aveas_format.converters", ("registry", "common", "labels")),
    Kind("rules", "aveas_format.validate.rules"),
    Kind("derivations", "aveas_format.derive", ("registry",)),
    Kind("commands", "aveas_format.cli", ("app", "common", "options")),
)}

_done: set[str] = set()
_loading: set[str] = set()
_failed: dict[str, PluginError] = {}
_installed: list[importlib.metadata.EntryPoints] = []  # every entry point, read once per process


def load(kind: str) -> None:
    """Import the built-in modules of ``kind``, then its plugins (once per process).

    A call made while the same kind is loading (a module asking for its own registry) returns at
    once. Raises PluginError when a plugin cannot be loaded (again on every later call).
    """
    k = KINDS[kind]
    if kind in _failed:
        raise _failed[kind]
    if kind in _done or kind in _loading:
        return
    _loading.add(kind)
    try:
        import_tree(k.package, skip=k.helpers)
        for ep in entry_points(kind):
            _load_plugin(k, ep)
    except PluginError as e:
        _failed[kind] = e
        raise
    finally:
        _loading.discard(kind)
    _done.add(kind)


def forget(kind: str | None = None) -> None:
    """Forget that ``kind`` (default: every kind) was loaded, so that the next :func:`load` looks
    for plugins again (after installing one at run time; tests). Modules already imported are not
    imported again, and what they registered stays registered."""
    for k in [kind] if kind else list(KINDS):
        _done.discard(k)
        _failed.pop(k, None)
    _installed.clear()


def import_tree(package: str, skip: Iterable[str] = ()) -> list[str]:
    """Import ``package`` and every module below it, by name, depth first; return their names.

    Left out: modules named with a leading ``_`` (with everything below them) and, at the top
    level, the names in ``skip``.
    """
    pkg = importlib.import_module(package)
    skip = set(skip)
    out: list[str] = []
    for m in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if m.name.startswith("_") or m.name in skip:
            continue
        name = f"{package}.{m.name}"
        if m.ispkg:
            out += [name, *import_tree(name)]
        else:
            importlib.import_module(name)
            out.append(name)
    return out


def entry_points(kind: str) -> list[importlib.metadata.EntryPoint]:
    """The installed entry points of ``kind``'s group, by name."""
    if not _installed:  # one scan of the installed distributions serves every kind
        _installed.append(importlib.metadata.entry_points())
    eps = _installed[0].select(group=KINDS[kind].group)
    return sorted(eps, key=lambda ep: (ep.name, ep.value))


def distribution(ep: importlib.metadata.EntryPoint) -> str:
    """``NAME VERSION`` of the distribution that declares ``ep`` (for messages)."""
    dist = getattr(ep, "dist", None)
    if dist is None:
        return "an unknown distribution"
    return f"{dist.name} {dist.version}"


def _load_plugin(k: Kind, ep: importlib.metadata.EntryPoint) -> None:
    try:
        ep.load()
    except Exception as e:  # noqa: BLE001 — any failure of a plugin's import is reported as one line
        lines = str(e).strip().splitlines()
        why = f"{type(e).__name__}: {lines[0]}" if lines else type(e).__name__
        raise PluginError(f"{k.name} plugin {ep.name!r} ({ep.value}) of {distribution(ep)} "
                          f"cannot be loaded: {why}") from None


__all__ = ["KINDS", "Kind", "distribution", "entry_points", "forget", "import_tree", "load"]
