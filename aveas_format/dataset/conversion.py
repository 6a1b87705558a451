"""Converting many sources at once: source files grouped into conversions, one recording each,
converted in parallel and (by default) validated, each summarised as a :class:`ConversionEntry`."""

from __future__ import annotations

import functools
import re
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from aveas_format.dataset.report import (
    DatasetReport,
    RecordingEntry,
    RuleCount,
    recording_facts,
    run_dataset,
)
from aveas_format.errors import AveasError
from aveas_format.parallel import TaskResult


class ConversionEntry(RecordingEntry):
    """One conversion (``path`` is its name): its input files, the recording written, its size
    and, when validated, its findings."""

    inputs: list[str]
    output: str
    participants: int
    states: int
    seconds: float = 0.0


def conversion_groups(inputs: Iterable[str | Path], group: str | None = None
                      ) -> dict[str, list[str]]:
    """Split source files into conversions: one per INPUT (a directory stands for its files), or,
    with ``group`` (a regular expression with one capture group applied to file names), one per
    distinct captured value — e.g. ``r"^(\\d+)_"`` for levelX's ``01_tracks.csv``, ``01_tracksMeta.csv``...

    Returns ``{name: [files]}``; the name becomes the output recording's stem.
    """
    files: list[Path] = []
    units: dict[str, list[str]] = {}
    for raw in inputs:
        p = Path(raw)
        members = sorted(q for q in p.iterdir() if q.is_file()) if p.is_dir() else [p]
        if group is None:
            name = p.name.split(".")[0] if not p.is_dir() else p.name
            if name in units:
                raise AveasError(f"two inputs would both become {name}.aveas: {raw}")
            units[name] = [str(q) for q in members]
        else:
            files.extend(members)
    if group is not None:
        try:
            rx = re.compile(group)
        except re.error as e:
            raise AveasError(f"--group {group!r} is not a regular expression: {e}") from None
        if rx.groups != 1:
            raise AveasError(f"--group {group!r} must have exactly one capture group")
        for q in files:
            m = rx.search(q.name)
            if m:
                units.setdefault(m.group(1), []).append(str(q))
        if not units:
            raise AveasError(f"--group {group!r} matched no input file name")
    return units


def convert_recording(item: tuple[str, list[str], str], *, source: str,
                      map_source: str | None, options: dict[str, Any] | None,
                      overwrite: bool = False, validate_result: bool = True) -> ConversionEntry:
    """One conversion (a task): ``(name, input files, output path)`` -> a written recording."""
    from aveas_format.converters.registry import convert

    name, files, output = item
    t0 = time.perf_counter()
    rec = convert(source, files, map_source=map_source, options=options)
    written = rec.write(output, overwrite=overwrite)
    counts: dict[str, int] = {}
    rules: list[RuleCount] = []
    if validate_result:
        from aveas_format.validate.runner import validate

        report = validate(written)
        counts = report.counts
        rules = [RuleCount.of(r) for r in report.results]
    return ConversionEntry(
        path=name, inputs=files, output=str(written), **recording_facts(rec.meta),
        participants=rec.participants.num_rows, states=rec.states.num_rows,
        counts=counts, rules=rules, seconds=round(time.perf_counter() - t0, 4))


def convert_dataset(inputs: Iterable[str | Path], *, source: str, output_dir: str | Path,
                    map_source: str | None = None, options: dict[str, Any] | None = None,
                    group: str | None = None, overwrite: bool = False, validate: bool = True,
                    workers: int | None = 1, scheduler: str | None = None, progress: bool = False,
                    on_result: Callable[[TaskResult], None] | None = None) -> DatasetReport:
    """Convert many sources, one recording each (see :func:`conversion_groups`), in parallel;
    a source that fails is reported and the others complete."""
    units = conversion_groups(inputs, group)
    out = Path(output_dir)
    out.mkdir(parents=True, exist_ok=True)
    items = [(name, files, str(out / f"{name}.aveas")) for name, files in units.items()]
    fn = functools.partial(convert_recording, source=source, map_source=map_source,
                           options=options, overwrite=overwrite, validate_result=validate)
    return run_dataset(fn, items, kind="convert", specs=list(units), workers=workers,
                       scheduler=scheduler, progress=progress, on_result=on_result,
                       name=lambda item: item[0])
