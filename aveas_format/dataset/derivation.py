"""Deriving a dataset: derived tables and events for every recording, written under an output
directory (same relative layout) or in place, each summarised as a :class:`DerivationEntry`."""

from __future__ import annotations

import functools
import os
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from aveas_format.dataset.discovery import file_path, is_url, local_copy
from aveas_format.dataset.report import DatasetReport, RecordingEntry, recording_facts, run_dataset
from aveas_format.errors import AveasError
from aveas_format.parallel import TaskResult


class DerivationEntry(RecordingEntry):
    """One derived recording: where it was written, what was derived, the derived tables' sizes,
    the number of events and its criticality summary (no findings: ``counts``/``rules`` empty)."""

    output: str
    derived: list[str]
    tables: dict[str, int]
    events: int
    min_ttc_s: float | None = None
    min_pet_s: float | None = None
    near_misses: int = 0
    hard_braking: int = 0
    seconds: float = 0.0


def output_path_for(path: str, root: str | None, output_dir: str | Path) -> Path:
    """Where a dataset member goes under ``output_dir``: its path relative to ``root`` (its
    common parent), keeping its form."""
    p = file_path(path)
    if is_url(p):
        rel = p.split("?", 1)[0].split("://", 1)[1].split("/", 1)[-1]
    elif root:
        rel = os.path.relpath(os.path.abspath(p), root)
    else:
        rel = Path(p).name
    return Path(output_dir) / rel


def derive_recording(path: str, *, only: list[str] | None = None,
                     params: dict[str, dict] | None = None, output: str | None = None,
                     overwrite: bool = False, in_place: bool = False) -> DerivationEntry:
    """Derive one recording (a task) and write it to ``output`` (or in place)."""
    from aveas_format.derive import criticality_summary, derive
    from aveas_format.io.reader import open_recording

    t0 = time.perf_counter()
    if in_place and is_url(path) and not path.startswith("file://"):
        raise AveasError("--in-place needs local recordings")
    with local_copy(path) as local:
        rec = open_recording(local)
        facts = recording_facts(rec.meta)
        ran = derive(rec, only=only, **(params or {}))
        target = local if in_place else output
        assert target is not None
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        written = rec.write(target, overwrite=in_place or overwrite)
    crit = criticality_summary(rec)
    return DerivationEntry(
        path=path, **facts, counts={}, rules=[], output=str(written), derived=ran,
        tables={f"derived/{n}": t.num_rows for n, t in rec.derived.items()},
        events=rec.events.num_rows if rec.events is not None else 0,
        min_ttc_s=(crit.get("min_ttc_s") or {}).get("value"),
        min_pet_s=(crit.get("min_pet_s") or {}).get("value"),
        near_misses=crit.get("near_misses", 0), hard_braking=crit.get("hard_braking", 0),
        seconds=round(time.perf_counter() - t0, 4),
    )


def _common_root(paths: list[str]) -> str | None:
    local = [os.path.abspath(file_path(p)) for p in paths
             if not is_url(p) or p.startswith("file://")]
    local = [p for p in local if os.path.exists(p)]  # a missing one fails; it has no place
    if not local:
        return None
    parents = [os.path.dirname(p.rstrip("/")) for p in local]
    return os.path.commonpath(parents) if parents else None


def _derive_task(item: tuple[str, str | None], **kw: Any) -> DerivationEntry:
    path, output = item
    return derive_recording(path, output=output, **kw)


def derive_dataset(paths: Iterable[str | Path], *, output_dir: str | Path | None = None,
                   in_place: bool = False, overwrite: bool = False,
                   only: list[str] | None = None, params: dict[str, dict] | None = None,
                   workers: int | None = 1, scheduler: str | None = None, progress: bool = False,
                   specs: list[str] | None = None,
                   on_result: Callable[[TaskResult], None] | None = None) -> DatasetReport:
    """Derive every recording, writing each under ``output_dir`` (same relative layout) or in
    place. The report's entries hold what was derived and each recording's criticality summary."""
    paths = [str(p) for p in paths]
    if (output_dir is None) == (not in_place):
        raise AveasError("give output_dir or in_place=True (one of them)")
    root = _common_root(paths)
    items = [(p, None if in_place else str(output_path_for(p, root, output_dir))) for p in paths]
    fn = functools.partial(_derive_task, only=only, params=params, overwrite=overwrite,
                           in_place=in_place)
    return run_dataset(fn, items, kind="derive", specs=specs or paths, fail_on="never",
                       workers=workers, scheduler=scheduler, progress=progress,
                       on_result=on_result, name=lambda item: item[0])
