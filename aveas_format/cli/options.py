"""The options several commands share, declared once, and the preambles that go with them.

Like ``rasterio.rio.options``: a command module takes its shared options from here instead of
spelling out ``typer.Option(...)`` again, and calls the helper that goes with the option.

- **Output**: :func:`overwrite_option` (``--overwrite``) and :func:`refuse_overwrite`, the check
  before writing (never overwrite without ``--overwrite``).
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
- **Parallel runs**: :func:`workers_option` (``--workers``) and :func:`scheduler_option`
  (``--scheduler``, a Dask cluster); :data:`SIMULATION_WORKERS` of the SUMO runs (``sim
  sensitivity``, ``fit``).

The factories take the command's own flag names and help texts where these differ today (``-j``
or ``-w``, default 0 or 1): the options keep the names they had; harmonising them is a later
change, made here. Error handling and exit codes stay in :mod:`aveas_format.cli.common`.
"""

from __future__ import annotations

import json
import typing
from collections.abc import Sequence
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


def refuse_overwrite(path: Path, overwrite: bool) -> None:
    """A usage error (exit 2) when ``path`` exists and ``--overwrite`` was not given."""
    if path.exists() and not overwrite:
        raise fail(f"{path}: exists; pass --overwrite to replace it", EXIT_USAGE)


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

    Values are read as JSON where they parse (numbers, booleans, lists), else as strings; a
    comma-separated string becomes a list for list-typed options.
    """
    out_: dict[str, Any] = {}
    fields = getattr(model, "model_fields", {})
    for pair in pairs:
        if "=" not in pair:
            raise ValueError(f"--option {pair!r}: expected KEY=VALUE")
        key, raw = pair.split("=", 1)
        key = key.strip().replace("-", "_")
        try:
            value: Any = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        if "." in key:  # KEY.NAME=VALUE: one entry of a dict option (parameter.Speed=60)
            head, name = key.split(".", 1)
            out_.setdefault(head, {})[name] = raw if isinstance(value, (dict, list)) else value
            continue
        ann = fields[key].annotation if key in fields else None
        if typing.get_origin(ann) in (list, tuple) and isinstance(value, str):
            value = [v for v in value.split(",") if v]
        out_[key] = value
    return out_


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

    paths = discover(specs)
    err.print(f"{doing} {len(paths)} recordings "
              + (f"on {scheduler}" if scheduler else f"with {workers or 'all'} worker(s)"))
    return paths


def print_failure(result: Any, *, red: bool = False) -> None:
    """``on_result`` of a dataset run: one line on stderr for each recording that failed, as it
    fails (the others complete); ``red`` marks the word with rich markup (``validate``)."""
    if result.ok:
        return
    if red:
        err.print(f"[red]failed[/red] {result.item}: {result.error}", markup=True, highlight=False)
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
def workers_option(short: str = "-j", *, default: int = 0, minimum: int | None = 0, scope: str = "",
                   help: str = "local worker processes (0 = one per core, 1 = in this process).") -> Any:
    """``--workers N`` with the command's short flag: local processes of a parallel run (0 = one
    per core); ``scope`` prefixes the help (``Dataset``: only when the arguments are a dataset)."""
    return typer.Option(default, "--workers", short, min=minimum, help=_scoped(scope, help))


def scheduler_option(*, scope: str = "", help: str = "address of a Dask scheduler "
                     "(tcp://HOST:PORT) (needs aveas-format[dask]).") -> Any:
    """``--scheduler ADDRESS``: run on a Dask cluster instead of local processes."""
    return typer.Option(None, "--scheduler", help=_scoped(scope, help))


#: ``--workers/-w`` of the commands that run SUMO simulations (``sim sensitivity``, ``fit``)
SIMULATION_WORKERS = workers_option("-w", default=1, minimum=None,
                                    help="Local processes (0 = one per core).")
