"""The options several commands share, declared once, and the preambles that go with them.

Like ``rasterio.rio.options``: a command module takes its shared options from here instead of
spelling out ``typer.Option(...)`` again, and calls the helper that goes with the option.

- **Output**: :func:`overwrite_option` (``--overwrite``) and the checks before writing, made
  before any work: :func:`check_output` (a file: never replaced without ``--overwrite``, and its
  directory must exist) and :func:`check_output_dir` (a
  directory of outputs: not an existing, non-empty one without ``--overwrite``). Companion files
  (the map of an OpenLABEL export) are outputs too: check each.
- **Format**: :func:`format_option` (``--format text|json``, for every command that prints
  something a machine may read; a wrong value gets the closest allowed one) and
  :func:`legacy_json_option` + :func:`output_format`, the hidden, deprecated ``--json``.
- **The CRS of an import** (``convert``): :func:`crs_option` (``--crs``).
- **Options of a converter or exporter** (``convert``, ``export``): :func:`option_pairs_option`
  (``--option/-O KEY=VALUE``) and :func:`options_file_option` (``--options FILE.json``), read by
  :func:`converter_options`; :func:`parse_option_pairs` also reads ``fit``'s metric options.
- **Validation** of what a command wrote: :func:`validate_option` (``--validate/--no-validate``)
  and :func:`validate_written` (``convert``, ``sim run``); the rule selection
  :func:`select_option`/:func:`ignore_option` with :func:`comma_list` and :func:`check_rules`
  (``validate``, ``catalog``).
- **Datasets** (``catalog``, ``validate``, ``derive``, ``convert --each``): the arguments
  :func:`recordings_argument` (a recording or a dataset) and :func:`dataset_argument`; the decision
  :func:`single_recording` (one recording, or a dataset); :func:`discover_dataset` (find the
  recordings, announce the run); :func:`print_failure` (each failed recording, as it fails);
  :func:`run_summary` (the JSON printed at the end).
- **Parallel runs**: :func:`workers_option` (``--workers/-j N``: local worker processes, 0 = one
  per core, the default, 1 = in this process; the same name, meaning and default in every
  command) and :func:`scheduler_option` (``--scheduler``, a Dask cluster); a converter that reads
  one input in parallel takes them, and shows its progress on a terminal, through
  :func:`converter_workers`.
- **Verbosity**: :func:`verbose_option` (``--verbose/-v``) and :func:`set_verbose`: the
  library's log (``logging``, level INFO: which reader read a file, how) on stderr.

To add a shared option: a factory here (``typer.Option(...)`` with its one help text) and the
helper that reads it; a command module then only names it. Error handling, exit codes and plain
output stay in :mod:`aveas_format.cli.common`.
"""

from __future__ import annotations

import json
import logging
import types
import typing
from collections.abc import Iterable, Sequence
from enum import Enum
from pathlib import Path
from typing import Any

import typer

from aveas_format.cli.common import EXIT_USAGE, err, fail, out


def _scoped(scope: str, text: str) -> str:
    """``"Dataset: local worker processes ..."``; without a scope, the text capitalised."""
    return f"{scope}: {text}" if scope else text[:1].upper() + text[1:]


# ----------------------------------------------------------------------------------------------
# output
def overwrite_option(help: str = "Replace an existing output.") -> Any:
    """``--overwrite``: replace an existing output (without it a command refuses to)."""
    return typer.Option(False, "--overwrite", help=help)


def check_output(path: Path | Iterable[Path], overwrite: bool) -> None:
    """Before any work, for each output file (the output and its companion files): a usage error
    (exit 2) when it exists and ``--overwrite`` was not given, or when its directory does not
    exist (said as such, not as a temporary file's name)."""
    for p in [path] if isinstance(path, Path) else list(path):
        p = Path(p)
        if p.exists() and not overwrite:
            raise fail(f"{p}: exists; pass --overwrite to replace it", EXIT_USAGE)
        parent = p.parent if str(p.parent) else Path(".")
        if not parent.is_dir():
            raise fail(f"{p}: cannot write: the directory {parent} does not exist"
                       if not parent.exists() else f"{p}: cannot write: {parent} is not a directory",
                       EXIT_USAGE)


def check_output_dir(path: Path, overwrite: bool) -> None:
    """Before any work, for an output directory (created, parents too): a usage error (exit 2)
    when it is a file, or an existing non-empty directory and ``--overwrite`` was not given (its
    files would be replaced)."""
    if path.exists() and not path.is_dir():
        raise fail(f"{path}: exists and is not a directory", EXIT_USAGE)
    if path.is_dir() and any(path.iterdir()) and not overwrite:
        raise fail(f"{path}: exists and is not empty; pass --overwrite to replace the files in it",
                   EXIT_USAGE)


# ----------------------------------------------------------------------------------------------
# format
class OutputFormat(str, Enum):
    """``--format`` of a command that prints text for people or JSON for machines."""

    text = "text"
    json = "json"


def event_figures_option() -> Any:
    """``--figures DIR``: one PNG per listed critical event (its paths on the map and the pair's
    TTC and DRAC with their 1-sigma bands)."""
    return typer.Option(None, "--figures", help="Write a figure of each listed event into this "
                        "directory (EVENT.png: the paths on the map, TTC and DRAC ± 1 std).")


def format_option(default: Enum = OutputFormat.text, *flags: str,
                  help: str = "Output format: text (for people) or json (for machines).") -> Any:
    """``--format FORMAT`` (the command's Enum of formats, :class:`OutputFormat` by default; extra
    ``flags`` such as ``-f`` where a command had them)."""
    return typer.Option(default, "--format", *flags, help=help)


def legacy_json_option() -> Any:
    """``--json``, the deprecated spelling of ``--format json`` (hidden; still works)."""
    return typer.Option(False, "--json", hidden=True, help="Deprecated: use --format json.")


def output_format(fmt: Enum, legacy_json: bool) -> str:
    """The format asked for: ``--format``, or ``json`` for the deprecated ``--json`` (with a
    note on stderr)."""
    if legacy_json:
        err.print("aveas-format: note: --json is deprecated; use --format json")
        return "json"
    return str(fmt.value)


# ----------------------------------------------------------------------------------------------
# options of a converter or exporter
def option_pairs_option(kind: str) -> Any:
    """``--option/-O KEY=VALUE`` of a ``kind`` (``Converter``, ``Exporter``); read with
    :func:`converter_options`."""
    return typer.Option(None, "--option", "-O", help=f"{kind} option KEY=VALUE (repeatable; see "
                        "docs/converters.md).")


def options_file_option(kind: str) -> Any:
    """``--options FILE.json`` of a ``kind`` (``Converter``, ``Exporter``)."""
    return typer.Option(None, "--options", help=f"{kind} options as a JSON file.")


def converter_name_option(help: str = "Converter name (see --list).") -> Any:
    """``--from/-f NAME``: the converter of an import (``convert``, ``validate FILE``)."""
    return typer.Option(None, "--from", "-f", help=help)


def map_option(help: str = "The OpenDRIVE map the data refers to.") -> Any:
    """``--map/-m MAP.xodr``: the map of an import (``convert``, ``validate FILE``)."""
    return typer.Option(None, "--map", "-m", help=help)


def crs_option() -> Any:
    """``--crs CRS`` of the importers: the recording's CRS where the map has no
    ``<geoReference>`` (the common import option ``crs``)."""
    return typer.Option(None, "--crs", help="The recording's CRS (PROJ string, EPSG:code or WKT) "
                        "where the map has no <geoReference>, e.g. '+proj=tmerc +lat_0=48.1 "
                        "+lon_0=11.5 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m' (a transverse "
                        "Mercator at the site).")


def parse_option_pairs(pairs: list[str], model: type) -> dict[str, Any]:
    """``["net_file=a.net.xml", "vtypes=a.rou.xml,b.rou.xml", "geo=true", "parameter.Speed=60"]``
    -> dict (``KEY.NAME=VALUE`` sets the entry ``NAME`` of the dict option ``KEY``).

    Each value is read by the type the options model declares for its key
    (:func:`coerce_option`): ``subject_id=1`` of a text option is the text ``"1"``, ``rate_hz=10``
    of a number option the number 10, ``geo=yes`` of a boolean true, a comma-separated list (or a
    JSON one) for list and tuple options; a value that does not fit is a ``ValueError`` naming
    the option and the type expected. Keys the model does not declare (and models without
    fields, ``fit``'s metric options) are read as JSON where they parse, else as text.
    """
    out_: dict[str, Any] = {}
    fields = getattr(model, "model_fields", {})
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--option {pair!r}: expected KEY=VALUE")
        key, raw = pair.split("=", 1)
        key = key.strip().replace("-", "_")
        if "." in key:  # KEY.NAME=VALUE: one entry of a dict option (parameter.Speed=60)
            head, name = key.split(".", 1)
            ann = fields[head].annotation if head in fields else None
            args = typing.get_args(_non_null(ann)) if typing.get_origin(_non_null(ann)) is dict else ()
            out_.setdefault(head, {})[name] = coerce_option(key, raw, args[1] if len(args) == 2 else None)
            continue
        out_[key] = coerce_option(key, raw, fields[key].annotation if key in fields else None)
    return out_


def _non_null(ann: Any) -> Any:
    """``T`` of ``T | None`` (other annotations as they are)."""
    if typing.get_origin(ann) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(ann) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return ann


_TRUE, _FALSE = {"true", "1", "yes", "on"}, {"false", "0", "no", "off"}


def _type_name(ann: Any) -> str:
    """How an option's type reads in a message: ``an integer``, ``one of 'deg', 'rad'``..."""
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Literal:
        return "one of " + ", ".join(repr(a) for a in args)
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_type_name(a) for a in args if a is not type(None))
    if origin in (list, tuple):
        inner = args[0] if args else str
        n = f"{len(args)} " if origin is tuple and args and args[-1] is not Ellipsis else ""
        return f"a comma-separated list of {n}{_type_name(inner).removeprefix('a ').removeprefix('an ')}s"
    if isinstance(ann, type) and issubclass(ann, Enum):
        return "one of " + ", ".join(repr(m.value) for m in ann)
    if origin is dict or ann is dict:
        return "a JSON object"
    return {bool: "a boolean (true/false)", int: "an integer", float: "a number",
            str: "a text", Path: "a path"}.get(ann, "a JSON value")


def coerce_option(key: str, raw: str, ann: Any) -> Any:
    """The text ``raw`` of ``-O key=raw`` as the type ``ann`` the options model declares: text,
    path, integer, number, boolean (true/false, 1/0, yes/no, on/off), a ``Literal`` or ``Enum``
    value, a list or tuple (comma-separated or JSON, each item by its type), a dict (JSON), ``T |
    None`` (``none``/``null`` for None). Without a declared type: JSON where it parses, else text.
    A value that fits none: ``ValueError("option KEY: expected an integer, got 'x'")``."""
    def bad() -> ValueError:
        return ValueError(f"option {key}: expected {_type_name(ann)}, got {raw!r}")

    if ann is None or ann is Any:
        try:
            return json.loads(raw)
        except json.JSONDecodeError:
            return raw
    origin, args = typing.get_origin(ann), typing.get_args(ann)
    text = raw.strip()
    if origin in (typing.Union, types.UnionType):
        if type(None) in args and text.lower() in ("none", "null", ""):
            return None
        members = [a for a in args if a is not type(None)]
        # the most specific reading first: a literal, then booleans, numbers, lists; text last
        rank = {bool: 1, int: 2, float: 3, Path: 5, str: 6}
        for a in sorted(members, key=lambda a: rank.get(a, 4 if typing.get_origin(a) is not typing.Literal else 0)):
            try:
                return coerce_option(key, raw, a)
            except ValueError:
                continue
        raise bad()
    if ann is str:
        return raw
    if ann is Path:
        return Path(raw)
    if ann is bool:
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise bad()
    if ann is int:
        try:
            return int(text)
        except ValueError:
            try:
                f = float(text)
            except ValueError:
                raise bad() from None
            if not f.is_integer():
                raise bad() from None
            return int(f)
    if ann is float:
        try:
            return float(text)
        except ValueError:
            raise bad() from None
    if origin is typing.Literal:
        for a in args:
            if str(a) == text or (isinstance(a, str) and a.lower() == text.lower()):
                return a
        from aveas_format.errors import did_you_mean

        raise ValueError(f"option {key}: expected {_type_name(ann)}, got {raw!r}"
                         f"{did_you_mean(text, [str(a) for a in args])}")
    if isinstance(ann, type) and issubclass(ann, Enum):
        for m in ann:
            if str(m.value) == text or m.name == text:
                return m.value
        raise bad()
    if origin in (list, tuple, set, frozenset):
        if text.startswith("["):
            try:
                items = json.loads(text)
            except json.JSONDecodeError:
                raise bad() from None
            items = [i if isinstance(i, str) else json.dumps(i) for i in items]
        else:
            items = [v.strip() for v in text.split(",") if v.strip()]
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(items) != len(args):
                raise ValueError(f"option {key}: expected {len(args)} comma-separated values, got "
                                 f"{len(items)} in {raw!r}")
            return [coerce_option(key, v, a) for v, a in zip(items, args)]
        inner = args[0] if args else None
        try:
            return [coerce_option(key, v, inner) for v in items]
        except ValueError:
            raise bad() from None
    if origin is dict or ann is dict:
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            raise bad() from None
        if not isinstance(value, dict):
            raise bad()
        return value
    try:  # anything else (a nested model...): JSON, else the text for pydantic to judge
        return json.loads(raw)
    except json.JSONDecodeError:
        return raw


def ask_unstated(conv: Any, raw: dict[str, Any]) -> None:
    """A usage error (exit 2), before any work, when a simulation (``sim run``) would write a
    stand-in for a value only a person knows (the partner, the start time, the licence) that
    the options do not give. (Imports go ahead and warn: :class:`~aveas_format.converters.
    registry.UnstatedWarning`.)"""
    from aveas_format.converters.registry import unstated_note

    missing = conv.unstated(raw)
    if missing:
        raise fail(unstated_note(conv.name, missing), EXIT_USAGE)


def converter_options(options_file: Path | None, pairs: list[str] | None, model: type) -> dict[str, Any]:
    """Options of a converter/exporter from ``--options FILE.json`` and ``-O KEY=VALUE`` pairs
    (pairs win); a usage error (exit 2) when the file or a pair cannot be read."""
    raw: dict[str, Any] = {}
    if options_file:
        try:
            raw.update(json.loads(options_file.read_text()))
        except (OSError, json.JSONDecodeError) as e:
            raise fail(f"{options_file}: cannot read options: {e}", EXIT_USAGE) from None
    try:
        raw.update(parse_option_pairs(pairs or [], model))
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None
    return raw


# ----------------------------------------------------------------------------------------------
# validation
def validate_option(help: str = "Validate the result and report errors (exit 1 when it has "
                    "any).") -> Any:
    """``--validate/--no-validate`` (default on)."""
    return typer.Option(True, "--validate/--no-validate", help=help)


def validate_written(path: Path) -> None:
    """``--validate`` of a command that wrote a recording: validate it; with errors, print the
    report on stdout and exit 1, else one line of counts on stderr."""
    import aveas_format
    from aveas_format.validate.render import render_text

    report = aveas_format.validate(path)
    if report.counts["error"]:
        out.print(render_text(report), end="")
        raise typer.Exit(1)
    err.print(f"valid: {report.counts['warning']} warnings, {report.counts['info']} info")


def select_option(help: str = "Run only these rules (codes or families, repeatable or "
                  "comma-separated).") -> Any:
    """``--select RULE``: the rules to run (read with :func:`comma_list`)."""
    return typer.Option(None, "--select", help=help)


def ignore_option(help: str = "Skip these rules (codes or families).") -> Any:
    """``--ignore RULE``: the rules to skip (read with :func:`comma_list`)."""
    return typer.Option(None, "--ignore", help=help)


def comma_list(values: list[str] | None) -> list[str] | None:
    """A repeatable option whose values may also be comma-separated, as one list (None when not
    given): ``["a,b", "c"]`` -> ``["a", "b", "c"]``."""
    return [p.strip() for item in values for p in item.split(",") if p.strip()] if values else None


def check_rules(select: list[str] | None, ignore: list[str] | None) -> None:
    """A usage error (exit 2) when ``--select``/``--ignore`` name an unknown rule or family;
    checked before a dataset run starts rather than once per recording."""
    from aveas_format.validate.registry import select_rules

    try:
        select_rules(select, ignore)
    except ValueError as e:
        raise fail(str(e), EXIT_USAGE) from None


# ----------------------------------------------------------------------------------------------
# datasets
def recordings_argument(default: Any = ..., *, urls: str = "URLs") -> Any:
    """``RECORDING...`` of a command that takes one recording or a dataset (see
    :func:`single_recording`); ``urls`` ends the help text."""
    return typer.Argument(default, metavar="RECORDING...", help="A recording (NAME.aveas "
                          "directory or NAME.aveas.zip), or a dataset: a directory of recordings, "
                          f"several paths, globs or {urls}.")


def dataset_argument() -> Any:
    """``DATASET...`` of a command that always takes a dataset."""
    return typer.Argument(..., metavar="DATASET...", help="Recordings: a directory of recordings, "
                          "paths, globs or URLs.")


def single_recording(specs: list[str]) -> Path | None:
    """The recording the arguments name, or None when they name a dataset (several arguments, a
    glob, a URL, a directory of recordings: :func:`aveas_format.dataset.is_dataset_spec`)."""
    from aveas_format.dataset import is_dataset_spec

    return None if is_dataset_spec(specs) else Path(specs[0])


def discover_dataset(specs: list[str], doing: str, workers: int, scheduler: str | None) -> list[str]:
    """The recordings of a dataset (:func:`aveas_format.dataset.discover`), announced on stderr:
    ``validating 12 recordings with all worker(s)``."""
    from aveas_format.dataset import discover

    if scheduler:  # the [dask] extra: said before any work
        from aveas_format.errors import require

        require("distributed", extra="dask", what="a Dask scheduler (--scheduler)")
    paths = discover(specs)
    err.print(f"{doing} {len(paths)} recording{'' if len(paths) == 1 else 's'} "
              + (f"on {scheduler}" if scheduler else f"with {workers or 'all'} worker(s)"))
    return paths


def print_failure(result: Any, *, red: bool = False) -> None:
    """``on_result`` of a dataset run: one line on stderr for each recording that failed, as it
    fails (the others complete); ``red`` marks the word with rich markup (``validate``)."""
    if result.ok:
        return
    if red:
        from rich.markup import escape

        err.print(f"[red]failed[/red] {escape(str(result.item))}: {escape(str(result.error))}",
                  markup=True, highlight=False)
    else:
        err.print(f"failed {result.item}: {result.error}", markup=False, highlight=False)


def run_summary(d: dict[str, Any], fields: Sequence[str], *, exit_code: bool = False) -> dict[str, Any]:
    """The JSON a dataset run prints on stdout, from its report's ``to_dict()``: the counts, the
    ``fields`` of each result, and each failure's path and error."""
    head = ["recordings", "completed", "failed", *(["exit_code"] if exit_code else []), "seconds"]
    return {**{k: d[k] for k in head},
            "results": [{k: e.get(k) for k in fields} for e in d["entries"]],
            "failures": [{"path": f["path"], "error": f["error"]} for f in d["failures"]]}


# ----------------------------------------------------------------------------------------------
# parallel runs
WORKERS_HELP = "local worker processes (0 = one per core, 1 = in this process)."


def workers_option(*, scope: str = "") -> Any:
    """``--workers/-j N``: local processes of a parallel run, the same in every command (0 = one
    per core, the default; 1 = in this process); ``scope`` prefixes the help (``Dataset``: only
    when the arguments are a dataset)."""
    return typer.Option(0, "--workers", "-j", min=0, help=_scoped(scope, WORKERS_HELP))


def converter_workers(raw: dict[str, Any], model: type, workers: int) -> dict[str, Any]:
    """``--workers`` into a converter's options where the converter reads one input in parallel
    (its options have ``workers``, e.g. ``openlabel``: blocks of frames in processes), and its
    progress shown on a terminal where it has ``progress``; an ``--option`` given explicitly
    wins."""
    fields = getattr(model, "model_fields", {})
    if "workers" in fields and "workers" not in raw:
        raw["workers"] = workers
    if "progress" in fields and "progress" not in raw:
        raw["progress"] = True
    return raw


def verbose_option() -> Any:
    """``--verbose/-v``: say on stderr how the work is done (:func:`set_verbose`)."""
    return typer.Option(False, "--verbose", "-v", help="Say on stderr how the work is done (e.g. "
                        "which reader read a file, in how many processes).")


def set_verbose(verbose: bool) -> None:
    """With ``--verbose``, the library's log messages of level INFO and above (logger
    ``aveas_format``) go to stderr as ``aveas-format: MESSAGE``; without it, none of INFO."""
    import logging

    log = logging.getLogger("aveas_format")
    if not verbose:  # (a run without it, after one with it in the same process: quiet again)
        for h in [h for h in log.handlers if isinstance(h, _Stderr)]:
            log.removeHandler(h)
        return
    if not any(isinstance(h, _Stderr) for h in log.handlers):
        handler = _Stderr()
        handler.setFormatter(logging.Formatter("aveas-format: %(message)s"))
        log.addHandler(handler)
    log.setLevel(logging.INFO)


class _Stderr(logging.StreamHandler):
    """A handler writing to stderr as it is when a message comes (the CLI's, or a test runner's)."""

    @property
    def stream(self):
        import sys

        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def scheduler_option(*, scope: str = "", help: str = "address of a Dask scheduler "
                     "(tcp://HOST:PORT) (needs aveas-format[dask]).") -> Any:
    """``--scheduler ADDRESS``: run on a Dask cluster instead of local processes."""
    return typer.Option(None, "--scheduler", help=_scoped(scope, help))
