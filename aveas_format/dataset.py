"""Datasets: many recordings, processed one task per recording, locally or on a Dask cluster.

>>> from aveas_format import dataset
>>> paths = dataset.discover("archive/")                      # directories, globs, lists, file:// URLs
>>> rep = dataset.validate_dataset(paths, workers=4)          # or scheduler="tcp://host:8786"
>>> rep.exit_code(), rep.counts, rep.worst[:3]
>>> table = dataset.catalog(paths, workers=4)                 # one row per recording (pyarrow.Table)
>>> speeds = dataset.per_vehicle_stats(paths, "mean_speed", filters={"road_type": "motorway"})

A dataset is a directory (searched recursively for ``NAME.aveas/`` directories holding a
``recording.json`` and for ``NAME.aveas.zip`` files), a glob, a single recording, or a list of
those. URLs go through :func:`pyarrow.fs.FileSystem.from_uri`: ``file://`` is read in place, any
other scheme pyarrow supports (``s3://``, ``gs://``, ``hdfs://``) is listed there and each recording is
copied to a temporary local directory inside the task that processes it (the reader needs local
files; see docs/datasets.md).

Every batch operation maps a module-level task function over the recordings with
:func:`aveas_format.parallel.run_tasks`: results stream back as they finish, and a recording that
raises, or crashes its worker, becomes an entry with its error while the others complete. Only small,
picklable summaries travel back to the caller; per-recording reports can be written by the workers
themselves (``reports_dir``), so a dataset of thousands of recordings never sits in one process.
"""

from __future__ import annotations

import contextlib
import functools
import glob
import hashlib
import html
import json
import os
import re
import shutil
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any

from aveas_format._version import __version__
from aveas_format.errors import AveasError
from aveas_format.parallel import TaskResult, run_tasks

_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
_GLOB = re.compile(r"[*?\[]")

# ------------------------------------------------------------------------------------------
# discovery


def is_recording(path: str | Path) -> bool:
    """A recording: a directory holding ``recording.json``, or a ``.zip`` file (``NAME.aveas.zip``)."""
    p = Path(path)
    if p.is_dir():
        return (p / "recording.json").is_file()
    return p.is_file() and p.name.lower().endswith(".zip")


def is_dataset_spec(specs: Iterable[str | Path]) -> bool:
    """Whether CLI arguments name a dataset (several recordings) rather than one recording: more
    than one argument, a glob, a URL, or a directory that is not itself a recording but holds some."""
    specs = [str(s) for s in specs]
    if len(specs) != 1:
        return len(specs) > 1
    s = specs[0]
    if _URL.match(s) or (_GLOB.search(s) and not Path(s).exists()):
        return True
    p = Path(s)
    if not p.is_dir() or is_recording(p) or p.name.endswith(".aveas"):
        return False
    return bool(_find_local(p))


def _find_local(root: Path) -> list[str]:
    """Recordings under a local directory (not descending into a recording)."""
    found: list[str] = []
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        if "recording.json" in filenames and d != root:
            found.append(str(d))
            dirnames[:] = []
            continue
        dirnames[:] = sorted(n for n in dirnames if not n.startswith("."))
        for f in sorted(filenames):
            if f.lower().endswith(".aveas.zip"):
                found.append(str(d / f))
    if (root / "recording.json").is_file():
        return [str(root)]
    return sorted(found)


def _find_remote(url: str) -> list[str]:
    import pyarrow.fs as pafs

    try:
        fs, base = _filesystem_from_uri(url)
    except (_pa_errors() + (ValueError, OSError)) as e:
        raise AveasError(f"{url}: cannot open this URL with pyarrow.fs: {e}") from None
    base = base.rstrip("/") or "/"
    top, sep, query = url.partition("?")  # keep options such as ?region=... on every URL
    top = top.rstrip("/")

    def uri(p: str) -> str:
        """The URL of a path below ``base``: ``url`` + the relative part (works for every scheme,
        whether or not the filesystem path holds the bucket or host)."""
        rel = p[len(base):].strip("/") if p.startswith(base) else ""
        return (f"{top}/{rel}" if rel else top) + sep + query

    info = fs.get_file_info(base)
    if info.type == pafs.FileType.NotFound:
        raise AveasError(f"{url}: not found")
    if info.type == pafs.FileType.File:
        return [uri(base)]
    if fs.get_file_info(base + "/recording.json").type == pafs.FileType.File:
        return [uri(base)]
    out: set[str] = set()
    for fi in fs.get_file_info(pafs.FileSelector(base, recursive=True)):
        if fi.type != pafs.FileType.File:
            continue
        if fi.base_name == "recording.json":
            parent = fi.path.rsplit("/", 1)[0]
            if ".aveas.zip" not in parent:
                out.add(parent)
        elif fi.base_name.lower().endswith(".aveas.zip"):
            out.add(fi.path)
    # drop recordings nested inside other recordings
    keep = sorted(p for p in out if not any(p != q and p.startswith(q + "/") for q in out))
    return [uri(p) for p in keep]


def _filesystem_from_uri(uri: str) -> tuple[Any, str]:
    """(pyarrow filesystem, path in it) of a URL (one place, for tests to replace)."""
    import pyarrow.fs as pafs

    return pafs.FileSystem.from_uri(uri)


def _pa_errors() -> tuple[type[BaseException], ...]:
    import pyarrow as pa

    return (pa.ArrowException,)


def discover(*specs: str | Path | Iterable[str | Path]) -> list[str]:
    """Every recording a dataset spec names, sorted and without duplicates.

    Each spec is a recording, a directory (searched recursively), a glob (``archive/**/*.aveas``,
    ``**`` recursive), a URL (``file:///data/archive``, ``s3://bucket/archive``), or a list of those.
    Raises :class:`AveasError` for a directory, glob or URL that holds no recording; a path that
    does not exist is kept (its task fails with "no such recording", the others still run).
    """
    flat: list[str] = []
    for s in specs:
        if isinstance(s, (str, Path)):
            flat.append(str(s))
        else:
            flat.extend(str(x) for x in s)
    out: list[str] = []
    for s in flat:
        if s.startswith("file://"):
            found = [r if not r.startswith("file://") else r[len("file://"):]
                     for r in _find_remote(s)]
        elif _URL.match(s):
            found = _find_remote(s)
        elif Path(s).exists():
            found = [s] if is_recording(s) else (_find_local(Path(s)) if Path(s).is_dir() else [s])
        elif _GLOB.search(s):
            found = []
            for m in sorted(glob.glob(s, recursive=True)):
                found.extend([m] if is_recording(m) else _find_local(Path(m)) if Path(m).is_dir()
                             else [])
        else:
            found = [s]  # a missing recording: its task reports "no such recording"
        if not found:
            raise AveasError(f"{s}: no recordings found (NAME.aveas/ with recording.json, or "
                             "NAME.aveas.zip)")
        out.extend(found)
    seen: set[str] = set()
    uniq = []
    for p in out:
        key = p if _URL.match(p) else os.path.normpath(os.path.abspath(p))
        if key not in seen:
            seen.add(key)
            uniq.append(p)
    return uniq


@contextlib.contextmanager
def local_copy(ref: str) -> Iterator[str]:
    """A local path for a recording reference: the path itself, or a temporary copy of a remote one."""
    if not _URL.match(ref):
        yield ref
        return
    if ref.startswith("file://"):
        yield ref[len("file://"):]
        return
    import pyarrow.fs as pafs

    fs, path = _filesystem_from_uri(ref)
    tmp = tempfile.mkdtemp(prefix="aveas-remote-")
    try:
        name = path.rstrip("/").rsplit("/", 1)[-1]
        target = os.path.join(tmp, name)
        if fs.get_file_info(path).type == pafs.FileType.File:
            pafs.copy_files(path, target, source_filesystem=fs,
                            destination_filesystem=pafs.LocalFileSystem())
        else:
            os.makedirs(target)
            pafs.copy_files(path, target, source_filesystem=fs,
                            destination_filesystem=pafs.LocalFileSystem())
        yield target
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def map_recordings(fn: Callable[[str], Any], paths: Iterable[str], *, workers: int | None = 1,
                   scheduler: str | None = None, progress: bool = False,
                   description: str = "recordings") -> Iterator[TaskResult]:
    """``fn(path)`` for every recording through :func:`~aveas_format.parallel.run_tasks`
    (``fn`` must be a module-level function or a :func:`functools.partial` of one)."""
    return run_tasks(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                     progress=progress, description=description)


def _meta_facts(path: str) -> dict[str, Any]:
    """partner, method, provenance, site... from recording.json only (cheap); {} when unreadable."""
    from aveas_format.io.container import Container
    from aveas_format.io.reader import read_meta

    try:
        with Container(path) as c:
            meta, _ = read_meta(c)
    except Exception:  # noqa: BLE001 — the caller reports the recording's real error
        return {}
    return _facts(meta)


def _facts(meta: Any) -> dict[str, Any]:
    site = meta.acquisition.site
    return {
        "recording_id": meta.recording_id, "partner": meta.acquisition.partner,
        "method": meta.acquisition.method.value, "provenance": meta.provenance.value,
        "site": site.name if site else None, "country": site.country if site else None,
        "road_type": site.road_type.value if site and site.road_type else None,
    }


def _report_name(path: str) -> str:
    """A file name for a recording's report, unique over the dataset."""
    base = re.sub(r"(\.aveas)?(\.zip)?/?$", "", path.rstrip("/")).rsplit("/", 1)[-1] or "recording"
    base = re.sub(r"[^A-Za-z0-9._-]", "_", base)
    return f"{base}-{hashlib.sha1(path.encode()).hexdigest()[:8]}"


# ------------------------------------------------------------------------------------------
# validation


def validate_recording(path: str, *, select: list[str] | None = None,
                       ignore: list[str] | None = None, config: Any = None, max_sample: int = 50,
                       reports_dir: str | None = None) -> dict[str, Any]:
    """Validate one recording (a task): a compact, picklable summary; the full report goes to
    ``reports_dir/NAME-HASH.json`` when given."""
    from aveas_format.validate import validate

    t0 = time.perf_counter()
    with local_copy(path) as local:
        facts = _meta_facts(local)
        report = validate(local, select=select, ignore=ignore, config=config,
                          max_sample=max_sample)
    report_file = None
    if reports_dir:
        from aveas_format.safeio import write_text_atomic

        report_file = str(Path(reports_dir) / f"{_report_name(path)}.json")
        write_text_atomic(report_file, report.to_json())
    return {
        "path": path, **facts,
        "counts": report.counts,
        "rules": [{"code": r.code, "severity": r.severity.value, "title": r.title,
                   "count": r.count} for r in report.results],
        "tool_failures": [{"code": f.code, "error": f.error} for f in report.failures],
        "format_version": report.format_version,
        "seconds": round(time.perf_counter() - t0, 4),
        "report_file": report_file,
    }


_SEV_RANK = {"error": 3, "warning": 2, "info": 1}


class DatasetReport:
    """The aggregate of many recordings' outcomes (validation or another batch operation).

    ``entries`` holds one compact summary per recording that completed, ``failed`` one
    ``{path, error, traceback}`` per recording that raised or crashed its worker.
    """

    def __init__(self, kind: str = "validate", specs: list[str] | None = None,
                 fail_on: str = "error") -> None:
        self.kind = kind
        self.specs = specs or []
        self.fail_on = fail_on
        self.entries: list[dict[str, Any]] = []
        self.failed: list[dict[str, Any]] = []
        self.seconds = 0.0
        self.runner: dict[str, Any] = {}

    def add(self, r: TaskResult) -> None:
        if r.ok:
            self.entries.append(r.value)
        else:
            self.failed.append({"path": str(r.item), **_meta_facts_safe(r.item),
                                "error": r.error, "traceback": r.traceback})

    # -- aggregates --------------------------------------------------------------------------
    @property
    def recordings(self) -> int:
        return len(self.entries) + len(self.failed)

    @property
    def counts(self) -> dict[str, int]:
        out = {"error": 0, "warning": 0, "info": 0}
        for e in self.entries:
            for k, v in (e.get("counts") or {}).items():
                out[k] = out.get(k, 0) + v
        return out

    def entry_exit_code(self, e: dict[str, Any]) -> int:
        if e.get("tool_failures"):
            return 3
        if self.fail_on == "never":
            return 0
        th = _SEV_RANK[self.fail_on]
        return 1 if any(r["count"] and _SEV_RANK[r["severity"]] >= th for r in e.get("rules", []))\
            else 0

    def exit_code(self) -> int:
        """The worst over the dataset: 3 if any recording failed (unreadable, crashed, tool
        failure), else 1 if any has findings at/above ``fail_on``, else 0."""
        if self.failed or any(e.get("tool_failures") for e in self.entries):
            return 3
        return max((self.entry_exit_code(e) for e in self.entries), default=0)

    def by_rule(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}
        for e in self.entries:
            for r in e.get("rules", []):
                d = out.setdefault(r["code"], {"severity": r["severity"], "title": r["title"],
                                               "count": 0, "recordings": 0})
                d["count"] += r["count"]
                d["recordings"] += 1 if r["count"] else 0
        return dict(sorted(out.items(), key=lambda kv: (-_SEV_RANK[kv[1]["severity"]],
                                                        -kv[1]["count"], kv[0])))

    def by_partner(self) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {}

        def slot(p: str | None) -> dict[str, Any]:
            return out.setdefault(p or "(unknown)", {"recordings": 0, "failed": 0, "valid": 0,
                                                      "error": 0, "warning": 0, "info": 0,
                                                      "rules": {}})
        for e in self.entries:
            d = slot(e.get("partner"))
            d["recordings"] += 1
            d["valid"] += 1 if self.entry_exit_code(e) == 0 else 0
            for k, v in (e.get("counts") or {}).items():
                d[k] = d.get(k, 0) + v
            for r in e.get("rules", []):
                d["rules"][r["code"]] = d["rules"].get(r["code"], 0) + r["count"]
        for f in self.failed:
            d = slot(f.get("partner"))
            d["recordings"] += 1
            d["failed"] += 1
        return dict(sorted(out.items()))

    def worst(self, n: int = 10) -> list[dict[str, Any]]:
        """The ``n`` worst recordings: failed first, then by errors, warnings, infos."""
        rows = [{"path": f["path"], "recording_id": f.get("recording_id"),
                 "partner": f.get("partner"), "status": "failed", "error": f["error"],
                 "counts": None} for f in self.failed]
        scored = sorted(self.entries, key=lambda e: (-bool(e.get("tool_failures")),
                                                     -e["counts"].get("error", 0),
                                                     -e["counts"].get("warning", 0),
                                                     -e["counts"].get("info", 0), e["path"]))
        for e in scored:
            if not any(e["counts"].values()) and not e.get("tool_failures"):
                continue
            rows.append({"path": e["path"], "recording_id": e.get("recording_id"),
                         "partner": e.get("partner"),
                         "status": "tool_failure" if e.get("tool_failures") else
                         ("findings" if self.entry_exit_code(e) else "valid"),
                         "error": "; ".join(f"{t['code']}: {t['error']}"
                                            for t in e.get("tool_failures", [])) or None,
                         "counts": e["counts"],
                         "top_rules": [r["code"] for r in e.get("rules", [])[:5]],
                         "report_file": e.get("report_file")})
        return rows[:n]

    def to_dict(self, top: int = 20) -> dict[str, Any]:
        return {
            "kind": self.kind, "dataset": self.specs, "tool_version": __version__,
            "fail_on": self.fail_on, "exit_code": self.exit_code(),
            "recordings": self.recordings, "completed": len(self.entries),
            "failed": len(self.failed),
            "valid": sum(1 for e in self.entries if self.entry_exit_code(e) == 0),
            "counts": self.counts, "by_rule": self.by_rule(), "by_partner": self.by_partner(),
            "worst": self.worst(top), "failures": self.failed,
            "entries": sorted(self.entries, key=lambda e: e["path"]),
            "seconds": round(self.seconds, 3), "runner": self.runner,
        }

    def to_json(self, top: int = 20) -> str:
        return json.dumps(self.to_dict(top), indent=2, default=str)

    def to_text(self) -> str:
        lines = []
        for e in sorted(self.entries, key=lambda e: e["path"]):
            c = e.get("counts") or {}
            code = self.entry_exit_code(e)
            status = {0: "ok", 1: "findings", 3: "tool-failure"}[code]
            lines.append(f"{e['path']}: {status} ({c.get('error', 0)} errors, "
                         f"{c.get('warning', 0)} warnings, {c.get('info', 0)} infos)")
        for f in sorted(self.failed, key=lambda f: f["path"]):
            lines.append(f"{f['path']}: FAILED {f['error']}")
        c = self.counts
        lines.append(f"{self.recordings} recordings: "
                     f"{sum(1 for e in self.entries if self.entry_exit_code(e) == 0)} valid, "
                     f"{sum(1 for e in self.entries if self.entry_exit_code(e) == 1)} with findings, "
                     f"{len(self.failed) + sum(1 for e in self.entries if e.get('tool_failures'))} "
                     f"failed; {c['error']} errors, {c['warning']} warnings, {c['info']} infos "
                     f"in {self.seconds:.1f} s")
        return "\n".join(lines) + "\n"

    def to_html(self, top: int = 20) -> str:
        return render_dataset_html(self.to_dict(top))


def _meta_facts_safe(item: Any) -> dict[str, Any]:
    if not isinstance(item, str) or _URL.match(item):
        return {}
    return _meta_facts(item)


def run_dataset(fn: Callable[[Any], Any], items: Iterable[Any], *, kind: str,
                specs: list[str] | None = None, fail_on: str = "error", workers: int | None = 1,
                scheduler: str | None = None, progress: bool = False,
                on_result: Callable[[TaskResult], None] | None = None,
                name: Callable[[Any], str] | None = None) -> DatasetReport:
    """Map ``fn`` over items (recording paths, or tuples whose ``name(item)`` names the
    recording) and collect a :class:`DatasetReport` (``on_result`` is called with every result as
    it arrives, e.g. to print it)."""
    items = [str(i) for i in items] if name is None else list(items)
    label = name or str
    rep = DatasetReport(kind, specs or [label(i) for i in items], fail_on)
    rep.runner = {"workers": None if scheduler else (workers or os.cpu_count()),
                  "scheduler": scheduler}
    t0 = time.perf_counter()
    for r in run_tasks(fn, items, workers=workers, scheduler=scheduler, progress=progress,
                       description=kind):
        r.item = label(r.item)
        rep.add(r)
        if on_result is not None:
            on_result(r)
    rep.seconds = time.perf_counter() - t0
    return rep


def validate_dataset(paths: Iterable[str | Path], *, select: list[str] | None = None,
                     ignore: list[str] | None = None, config: Any = None, max_sample: int = 50,
                     reports_dir: str | Path | None = None, fail_on: str = "error",
                     workers: int | None = 1, scheduler: str | None = None,
                     progress: bool = False, specs: list[str] | None = None,
                     on_result: Callable[[TaskResult], None] | None = None,
                     task: Callable[[str], Any] | None = None) -> DatasetReport:
    """Validate every recording; one task per recording (``task`` replaces the default one, e.g.
    a wrapper; it must return what :func:`validate_recording` returns)."""
    if reports_dir is not None:
        Path(reports_dir).mkdir(parents=True, exist_ok=True)
    fn = task or functools.partial(validate_recording, select=select, ignore=ignore,
                                   config=config, max_sample=max_sample,
                                   reports_dir=str(reports_dir) if reports_dir else None)
    return run_dataset(fn, [str(p) for p in paths], kind="validate", specs=specs,
                       fail_on=fail_on, workers=workers, scheduler=scheduler, progress=progress,
                       on_result=on_result)


# ------------------------------------------------------------------------------------------
# derivation


def output_path_for(path: str, root: str | None, output_dir: str | Path) -> Path:
    """Where a dataset member goes under ``output_dir``: its path relative to ``root`` (its
    common parent), keeping its form."""
    p = path[len("file://"):] if path.startswith("file://") else path
    if _URL.match(p):
        rel = p.split("?", 1)[0].split("://", 1)[1].split("/", 1)[-1]
    elif root:
        rel = os.path.relpath(os.path.abspath(p), root)
    else:
        rel = Path(p).name
    return Path(output_dir) / rel


def derive_recording(path: str, *, only: list[str] | None = None,
                     params: dict[str, dict] | None = None, output: str | None = None,
                     overwrite: bool = False, in_place: bool = False) -> dict[str, Any]:
    """Derive one recording (a task) and write it to ``output`` (or in place)."""
    import aveas_format
    from aveas_format.derive import criticality_summary, derive

    t0 = time.perf_counter()
    if in_place and _URL.match(path) and not path.startswith("file://"):
        raise AveasError("--in-place needs local recordings")
    with local_copy(path) as local:
        rec = aveas_format.open(local)
        facts = _facts(rec.meta)
        ran = derive(rec, only=only, **(params or {}))
        target = local if in_place else output
        assert target is not None
        Path(target).parent.mkdir(parents=True, exist_ok=True)
        written = rec.write(target, overwrite=in_place or overwrite)
    crit = criticality_summary(rec)
    return {
        "path": path, **facts, "output": str(written), "derived": ran,
        "tables": {f"derived/{n}": t.num_rows for n, t in rec.derived.items()},
        "events": rec.events.num_rows if rec.events is not None else 0,
        "min_ttc_s": (crit.get("min_ttc_s") or {}).get("value"),
        "min_pet_s": (crit.get("min_pet_s") or {}).get("value"),
        "near_misses": crit.get("near_misses", 0), "hard_braking": crit.get("hard_braking", 0),
        "counts": {}, "rules": [],
        "seconds": round(time.perf_counter() - t0, 4),
    }


def _common_root(paths: list[str]) -> str | None:
    local = [os.path.abspath(p[7:] if p.startswith("file://") else p) for p in paths
             if not _URL.match(p) or p.startswith("file://")]
    local = [p for p in local if os.path.exists(p)]  # a missing one fails; it has no place
    if not local:
        return None
    parents = [os.path.dirname(p.rstrip("/")) for p in local]
    return os.path.commonpath(parents) if parents else None


def _derive_task(item: tuple[str, str | None], **kw: Any) -> dict[str, Any]:
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


# ------------------------------------------------------------------------------------------
# catalog

#: the classes of the taxonomy, one ``n_CLASS`` column each in the catalog
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
                      overwrite: bool = False, validate_result: bool = True) -> dict[str, Any]:
    """One conversion (a task): ``(name, input files, output path)`` -> a written recording."""
    from aveas_format.converters.registry import convert

    name, files, output = item
    t0 = time.perf_counter()
    rec = convert(source, files, map_source=map_source, options=options)
    written = rec.write(output, overwrite=overwrite)
    entry: dict[str, Any] = {
        "path": name, "inputs": files, "output": str(written), **_facts(rec.meta),
        "participants": rec.participants.num_rows, "states": rec.states.num_rows,
        "counts": {}, "rules": [],
    }
    if validate_result:
        import aveas_format

        report = aveas_format.validate(written)
        entry["counts"] = report.counts
        entry["rules"] = [{"code": r.code, "severity": r.severity.value, "title": r.title,
                           "count": r.count} for r in report.results]
    entry["seconds"] = round(time.perf_counter() - t0, 4)
    return entry


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


def _classes() -> list[str]:
    from aveas_format.schema.taxonomy import CLASSES

    return list(CLASSES)


def catalog_schema():
    """The pyarrow schema of the catalog (one row per recording)."""
    import pyarrow as pa

    fields = [
        ("path", pa.string()), ("recording_id", pa.string()), ("title", pa.string()),
        ("format_version", pa.string()), ("partner", pa.string()), ("method", pa.string()),
        ("provenance", pa.string()), ("site", pa.string()), ("country", pa.string()),
        ("road_type", pa.string()), ("start_time", pa.timestamp("ns", tz="UTC")),
        ("duration_s", pa.float64()), ("nominal_rate_hz", pa.float64()),
        ("lon", pa.float64()), ("lat", pa.float64()), ("crs", pa.string()),
        ("coverage_area_m2", pa.float64()), ("right_of_use", pa.string()),
        ("license", pa.string()), ("n_participants", pa.int64()), ("n_states", pa.int64()),
        ("participants_per_class", pa.map_(pa.string(), pa.int64())),
        *[(f"n_{c}", pa.int64()) for c in _classes()],
        ("tables", pa.list_(pa.string())), ("derived", pa.list_(pa.string())),
        ("size_bytes", pa.int64()),
        ("validated", pa.bool_()), ("valid", pa.bool_()), ("errors", pa.int64()),
        ("warnings", pa.int64()), ("infos", pa.int64()), ("rules_failed", pa.list_(pa.string())),
        ("min_ttc_s", pa.float64()), ("min_pet_s", pa.float64()), ("near_misses", pa.int64()),
        ("hard_braking", pa.int64()),
        ("read_error", pa.string()),
    ]
    return pa.schema([pa.field(n, t) for n, t in fields])


def _size(path: str) -> int | None:
    p = Path(path)
    if p.is_file():
        return p.stat().st_size
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    return None


def _finite_min(table: Any, column: str) -> float | None:
    import numpy as np

    if table is None or column not in table.column_names or not table.num_rows:
        return None
    a = table.column(column).to_numpy(zero_copy_only=False).astype(float)
    a = a[np.isfinite(a)]
    return float(a.min()) if a.size else None


def catalog_row(path: str, *, validate: bool = True, select: list[str] | None = None,
                ignore: list[str] | None = None, config: Any = None) -> dict[str, Any]:
    """One catalog row (a task): recording.json, the participants table, the footer of states,
    the ``ttc``/``pet`` columns of derived tables and the kinds of events — never whole states.
    ``validate=True`` runs the validator for the validity columns."""
    import numpy as np
    import pyarrow.compute as pc
    import shapely

    import aveas_format
    from aveas_format.io.container import Container
    from aveas_format.io.reader import read_meta, table_names_present

    with local_copy(path) as local:
        with Container(local) as c:
            meta, _ = read_meta(c)
            present = table_names_present(c, meta)
        small = [t for t in ("participants", "derived/interactions", "derived/encroachments",
                             "events") if t in present]
        rec = aveas_format.open(local, tables=small, verify=False, columns={
            "derived/interactions": ["ttc"], "derived/encroachments": ["pet"],
            "events": ["kind", "origin"]})
        row: dict[str, Any] = {"path": path, **_facts(meta)}
        row.update(title=meta.title, format_version=meta.format_version,
                   start_time=meta.start_time, duration_s=meta.duration_s,
                   nominal_rate_hz=meta.nominal_rate_hz, lon=meta.location.lon,
                   lat=meta.location.lat, crs=meta.crs,
                   right_of_use=meta.rights.right_of_use.value, license=meta.rights.license,
                   tables=present, derived=[t for t in present if t.startswith("derived/")],
                   size_bytes=_size(local))
        area = None
        if meta.coverage:
            with contextlib.suppress(Exception):
                area = float(shapely.from_wkt(meta.coverage).area)
        row["coverage_area_m2"] = area
        entry = meta.tables.get("states")
        row["n_states"] = entry.rows if entry is not None else None
        p = rec.participants
        per_class: dict[str, int] = {}
        if p is not None and p.num_rows:
            for d in pc.value_counts(p.column("class").cast("string")).to_pylist():
                per_class[d["values"]] = int(d["counts"])
        row["n_participants"] = p.num_rows if p is not None else None
        row["participants_per_class"] = sorted(per_class.items())
        for cl in _classes():
            row[f"n_{cl}"] = per_class.get(cl, 0)
        row["min_ttc_s"] = _finite_min(rec.derived.get("interactions"), "ttc")
        row["min_pet_s"] = _finite_min(rec.derived.get("encroachments"), "pet")
        ev = rec.events
        if ev is not None and ev.num_rows:
            kind = np.asarray(ev.column("kind").cast("string").to_pylist(), dtype=object)
            origin = np.asarray(ev.column("origin").cast("string").to_pylist(), dtype=object)
            der = origin == "derived"
            row["near_misses"] = int(((kind == "near_miss") & der).sum())
            row["hard_braking"] = int(((kind == "hard_braking") & der).sum())
        else:
            row["near_misses"] = row["hard_braking"] = 0
        row["validated"] = validate
        if validate:
            from aveas_format.validate import validate as run

            rep = run(local, select=select, ignore=ignore, config=config, max_sample=1)
            c = rep.counts
            row.update(errors=c["error"], warnings=c["warning"], infos=c["info"],
                       valid=(not rep.failures and c["error"] == 0),
                       rules_failed=sorted(rep.codes() | {f.code for f in rep.failures}))
    return row


def catalog(paths: Iterable[str | Path], *, validate: bool = True, workers: int | None = 1,
            scheduler: str | None = None, progress: bool = False,
            select: list[str] | None = None, ignore: list[str] | None = None,
            on_result: Callable[[TaskResult], None] | None = None):
    """The catalog of a dataset as a :class:`pyarrow.Table` (schema :func:`catalog_schema`), one
    row per recording; a recording that cannot be read gets a row with ``read_error`` set."""
    import pyarrow as pa

    fn = functools.partial(catalog_row, validate=validate, select=select, ignore=ignore)
    rows = []
    for r in map_recordings(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                            progress=progress, description="catalog"):
        if on_result is not None:
            on_result(r)
        rows.append(r.value if r.ok else {"path": r.item, **_meta_facts_safe(r.item),
                                          "read_error": r.error})
    rows.sort(key=lambda d: d["path"])
    schema = catalog_schema()
    cols = {f.name: [row.get(f.name) for row in rows] for f in schema}
    cols["start_time"] = [_ts(v) for v in cols["start_time"]]
    return pa.Table.from_pydict(cols, schema=schema)


def _ts(v: Any) -> Any:
    if v is None or not isinstance(v, str):
        return v
    from datetime import datetime

    return datetime.fromisoformat(v.replace("Z", "+00:00"))


def write_catalog(table: Any, path: str | Path) -> Path:
    """Write the catalog: Parquet (``.parquet``), CSV (``.csv``) or JSON lines (``.jsonl``)."""
    import pyarrow as pa

    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    suffix = p.suffix.lower()
    if suffix == ".csv":
        import pyarrow.csv as pacsv

        flat = table.drop_columns(["participants_per_class", "tables", "derived", "rules_failed"])
        for name in ("tables", "derived", "rules_failed"):
            flat = flat.append_column(name, pa.array(
                [";".join(v) if v else None for v in table.column(name).to_pylist()], pa.string()))
        pacsv.write_csv(flat, tmp)
    elif suffix in (".jsonl", ".ndjson"):
        with open(tmp, "w", encoding="utf-8") as f:
            for row in table.to_pylist():
                f.write(json.dumps(row, default=str) + "\n")
    else:
        import pyarrow.parquet as pq

        pq.write_table(table, tmp)
    os.replace(tmp, p)
    return p


# ------------------------------------------------------------------------------------------
# dataset-wide statistics

def _speed(t):
    import numpy as np

    vx = t.column("vx").to_numpy(zero_copy_only=False).astype(float)
    vy = t.column("vy").to_numpy(zero_copy_only=False).astype(float)
    return np.hypot(vx, vy)


#: name -> (states columns needed, per-sample values from the states table, reducer)
METRICS: dict[str, tuple[tuple[str, ...], Callable[[Any], Any], str]] = {
    "mean_speed": (("vx", "vy"), _speed, "mean"),
    "max_speed": (("vx", "vy"), _speed, "max"),
    "min_speed": (("vx", "vy"), _speed, "min"),
    "speed_std": (("vx", "vy"), _speed, "std"),
    "observed_s": ((), lambda t: t.column("time").to_numpy(zero_copy_only=False), "span"),
    "samples": ((), lambda t: t.column("time").to_numpy(zero_copy_only=False), "count"),
    "mean_lateral_offset": (("lane_offset",), lambda t: t.column("lane_offset").to_numpy(
        zero_copy_only=False).astype(float), "mean"),
}


def _matches(facts: Mapping[str, Any], filters: Mapping[str, Any] | None) -> bool:
    for key, want in (filters or {}).items():
        have = facts.get(key)
        if callable(want):
            if not want(have):
                return False
        elif isinstance(want, (list, tuple, set, frozenset)):
            if have not in want:
                return False
        elif have != want:
            return False
    return True


def per_vehicle_task(path: str, *, metric: str, filters: Mapping[str, Any] | None = None,
                     classes: list[str] | None = None) -> dict[str, Any] | None:
    """One recording's per-participant values of ``metric`` (a task): None when the recording's
    metadata does not match ``filters``; reads only the states columns the metric needs."""
    import numpy as np

    import aveas_format
    from aveas_format.io.container import Container
    from aveas_format.io.reader import read_meta

    cols, values_of, how = METRICS[metric]
    with local_copy(path) as local:
        with Container(local) as c:
            meta, _ = read_meta(c)
        facts = _facts(meta)
        if not _matches(facts, filters):
            return None
        parts = aveas_format.open(local, tables=["participants"], verify=False,
                                  columns={"participants": ["class"]}).participants
        pids_wanted = None
        if classes:
            pc_cls = np.asarray(parts.column("class").cast("string").to_pylist(), dtype=object)
            pids_wanted = parts.column("participant_id").to_numpy()[np.isin(pc_cls, classes)]
            if not len(pids_wanted):
                return {**facts, "path": path, "participant_id": [], "class": [], "value": []}
        st = aveas_format.open(local, tables=["states"], columns=list(cols), verify=False,
                               participants=pids_wanted).states
    pid = st.column("participant_id").to_numpy()
    v = values_of(st)
    order = np.argsort(pid, kind="stable")
    pid, v = pid[order], v[order]
    ids, start = np.unique(pid, return_index=True)
    out = []
    for seg in np.split(v, start[1:]) if len(ids) else []:
        seg = seg[np.isfinite(seg)] if seg.dtype.kind == "f" else seg
        if not len(seg):
            out.append(np.nan)
        elif how == "mean":
            out.append(float(np.mean(seg)))
        elif how == "max":
            out.append(float(np.max(seg)))
        elif how == "min":
            out.append(float(np.min(seg)))
        elif how == "std":
            out.append(float(np.std(seg)))
        elif how == "span":
            out.append(float(np.max(seg) - np.min(seg)))
        else:
            out.append(float(len(seg)))
    cls_of = dict(zip(parts.column("participant_id").to_pylist(),
                      parts.column("class").cast("string").to_pylist()))
    return {**facts, "path": path, "participant_id": ids.tolist(),
            "class": [cls_of.get(int(i)) for i in ids], "value": out}


def per_vehicle_stats(paths: Iterable[str | Path], metric: str = "mean_speed", *,
                      filters: Mapping[str, Any] | None = None,
                      classes: list[str] | None = None, workers: int | None = 1,
                      scheduler: str | None = None, progress: bool = False,
                      errors: list[dict[str, Any]] | None = None):
    """Per-vehicle values of ``metric`` over a dataset as a :class:`pyarrow.Table` (columns
    recording_id, partner, method, road_type, participant_id, class, value), streamed one
    recording at a time: each task reads only recording.json, the participants' classes and the
    states columns the metric needs.

    metric: a key of :data:`METRICS` (mean_speed, max_speed, min_speed, speed_std, observed_s,
    samples, mean_lateral_offset). filters: recording.json facts to match (partner, method,
    provenance, site, country, road_type, recording_id), each a value, a list of values or a
    predicate (a predicate must be picklable for worker processes). classes: participant classes
    to keep. A recording that fails is left out and, when ``errors`` is a list, appended to it.
    """
    import pyarrow as pa

    if metric not in METRICS:
        raise AveasError(f"unknown metric {metric!r}; known: {', '.join(METRICS)}")
    fn = functools.partial(per_vehicle_task, metric=metric, filters=dict(filters or {}),
                           classes=list(classes) if classes else None)
    cols: dict[str, list] = {k: [] for k in ("recording_id", "partner", "method", "road_type",
                                             "participant_id", "class", "value")}
    for r in map_recordings(fn, [str(p) for p in paths], workers=workers, scheduler=scheduler,
                            progress=progress, description=metric):
        if not r.ok:
            if errors is not None:
                errors.append({"path": r.item, "error": r.error})
            continue
        d = r.value
        if d is None:
            continue
        n = len(d["value"])
        for k in ("recording_id", "partner", "method", "road_type"):
            cols[k].extend([d[k]] * n)
        cols["participant_id"].extend(d["participant_id"])
        cols["class"].extend(d["class"])
        cols["value"].extend(d["value"])
    schema = pa.schema([("recording_id", pa.string()), ("partner", pa.string()),
                        ("method", pa.string()), ("road_type", pa.string()),
                        ("participant_id", pa.int64()), ("class", pa.string()),
                        ("value", pa.float64())])
    return pa.Table.from_pydict(cols, schema=schema)


# ------------------------------------------------------------------------------------------
# HTML


def render_dataset_html(d: dict[str, Any]) -> str:
    """A self-contained HTML page of a dataset report (``DatasetReport.to_dict()``)."""
    e = html.escape

    def table(head: list[str], rows: list[list[Any]]) -> str:
        if not rows:
            return "<p><em>none</em></p>"
        h = "".join(f"<th>{e(str(x))}</th>" for x in head)
        body = "".join("<tr>" + "".join(f"<td>{e('' if v is None else str(v))}</td>" for v in r)
                       + "</tr>" for r in rows)
        return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"

    c = d["counts"]
    status = {0: "passed", 1: "findings", 3: "failures"}.get(d["exit_code"], str(d["exit_code"]))
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>aveas-format {e(d['kind'])} report: {d['recordings']} recordings</title>",
        "<style>body{font-family:system-ui,sans-serif;margin:2em;max-width:80em}"
        "table{border-collapse:collapse;margin:.5em 0 1.5em}td,th{border:1px solid #ccc;"
        "padding:.25em .6em;text-align:left;font-size:.9em}th{background:#f3f3f3}"
        ".s{font-size:1.1em}.passed{color:#1a7f37}.findings{color:#9a6700}"
        ".failures{color:#cf222e}</style></head><body>",
        f"<h1>Dataset {e(d['kind'])} report</h1>",
        f"<p class='s'>{d['recordings']} recordings: {d.get('valid', 0)} valid, "
        f"{d['failed']} failed to process; {c.get('error', 0)} errors, "
        f"{c.get('warning', 0)} warnings, {c.get('info', 0)} infos. Status: "
        f"<b class='{status}'>{status}</b> (exit code {d['exit_code']}, fail-on "
        f"{e(str(d['fail_on']))}), {d['seconds']} s, tool {e(d['tool_version'])}.</p>",
        f"<p>Dataset: {e(', '.join(map(str, d['dataset']))[:2000])}</p>",
        "<h2>Findings by rule</h2>",
        table(["rule", "severity", "title", "findings", "recordings"],
              [[k, v["severity"], v["title"], v["count"], v["recordings"]]
               for k, v in d["by_rule"].items()]),
        "<h2>By partner</h2>",
        table(["partner", "recordings", "valid", "failed", "errors", "warnings", "infos",
               "top rules"],
              [[k, v["recordings"], v["valid"], v["failed"], v["error"], v["warning"], v["info"],
                ", ".join(f"{r} ({n})" for r, n in sorted(v["rules"].items(),
                                                           key=lambda kv: -kv[1])[:5])]
               for k, v in d["by_partner"].items()]),
        "<h2>Worst recordings</h2>",
        table(["recording", "id", "partner", "status", "errors", "warnings", "infos", "rules",
               "error"],
              [[w["path"], w.get("recording_id"), w.get("partner"), w["status"],
                *((w["counts"] or {}).get(k) for k in ("error", "warning", "info")),
                ", ".join(w.get("top_rules") or []), w.get("error")] for w in d["worst"]]),
        *([] if d["kind"] == "validate" else [
            "<h2>Recordings</h2>",
            table(["recording", "id", "partner", "output", "derived", "events", "min TTC (s)",
                   "min PET (s)", "near misses", "hard braking", "seconds"],
                  [[x["path"], x.get("recording_id"), x.get("partner"), x.get("output"),
                    ", ".join(x.get("derived") or []), x.get("events"), _fmt(x.get("min_ttc_s")),
                    _fmt(x.get("min_pet_s")), x.get("near_misses"), x.get("hard_braking"),
                    x.get("seconds")] for x in d["entries"]])]),
        "<h2>Recordings that failed</h2>",
        table(["recording", "error"], [[f["path"], f["error"]] for f in d["failures"]]),
        "</body></html>\n",
    ]
    return "".join(parts)


def _fmt(v: Any) -> str:
    return "" if v is None else f"{v:.3g}"
