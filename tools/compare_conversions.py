"""Do two source trees convert the same inputs to the same recordings? (A refactoring of the
importers must not change what they write.)

Three steps, each a subcommand (``python tools/compare_conversions.py STEP ...``):

``capture CORPUS [PYTEST ARGS]``
    runs pytest on the importers' tests with this module as a plugin: every call of an importer
    (``Converter.__call__``) is recorded into ``CORPUS/cases.json`` with copies of its input
    files (the whole folder of each input and option path: sidecar files are found by name),
    so that fixtures the tests write into temporary folders can be converted again later. Files
    under ``../shared/data`` and the tests' committed data are referenced where they are. The
    real files under ``../shared/data`` that the non-OpenLABEL importers take are added as cases
    of their own (:data:`REAL`).
``run TREE CORPUS OUT``
    converts every case with the package of the source tree ``TREE`` (a subprocess with
    ``PYTHONPATH=TREE``): ``OUT/NNNN/rec.aveas`` or ``OUT/NNNN/error.json`` (exception type and
    message), and the warnings and located source findings it gave (``OUT/NNNN/said.json``).
``compare OUT_A OUT_B``
    every table of the two recordings of each case equal as Arrow tables (schema and values),
    recording.json equal up to ``recording_id`` (a new UUID per run), errors and warnings equal;
    prints one line per difference and a summary; exit 1 on a difference.

Example (the baseline worktree against this one)::

    python tools/compare_conversions.py capture /tmp/corpus
    git worktree add ../base BASE_COMMIT
    python tools/compare_conversions.py run ../base /tmp/corpus /tmp/out-base
    python tools/compare_conversions.py run . /tmp/corpus /tmp/out-new
    python tools/compare_conversions.py compare /tmp/out-base /tmp/out-new
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"

#: the importers' tests whose conversions are captured (OpenLABEL's are another engineer's)
TESTS = [f"tests/converters/test_{m}.py" for m in (
    "accident", "driving_simulator", "infra_lidar", "infra_lwir", "levelx", "osi", "osi_columns",
    "ros2_mcap", "rotated_boxes", "sumo_fcd", "openscenario_import", "openscenario")] + [
    f"tests/realdata/test_{m}.py" for m in ("mot", "openscenario", "osi", "sumo")] + [
    "tests/security/test_degenerate_sources.py"]

#: the real files of ../shared/data the non-OpenLABEL importers take: (converter, inputs, map,
#: options, crs) with paths relative to ../shared/data
_TMERC = "+proj=tmerc +lat_0=57.7 +lon_0=11.97 +k=1 +x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs"
_STATED = {"partner": "test", "license": "CC0-1.0"}
REAL: list[tuple[str, list[str], str | None, dict, str | None]] = [
    ("sumo-fcd", ["sumo/fcd_cartesian_excerpt.xml"], "real/sumo/road.xodr", {}, None),
    ("sumo-fcd", ["real/sumo/fcd_default_lanechanges.xml.gz"], "real/sumo/road.xodr", {}, None),
    ("sumo-fcd", ["real/sumo/fcd_default_lanechanges.xml.gz"], "real/sumo/road.xodr",
     {"lane_change_duration": 3.0, "vtypes": ["real/sumo/r.rou.xml"]}, None),
    ("osi", ["real/omega-prime/alks_cut-in.osi"], "real/omega-prime/straight_500m.xodr", _STATED, _TMERC),
    ("osi", ["real/omega-prime/acc-test.osi"], "real/omega-prime/straight_500m.xodr", _STATED, _TMERC),
] + [("openscenario", [f"real/esmini/{p}"], None, {}, _TMERC) for p in (
    "resources/xosc/trajectory-test.xosc", "resources/xosc/lane-change_trajectory_wp.xosc",
    "resources/xosc/pedestrian_traj_synch.xosc",
    "EnvironmentSimulator/Unittest/xosc/traj_use_cases.xosc")]


# --- capture (a pytest plugin) ---------------------------------------------------------------------

class _Recorder:
    def __init__(self, corpus: Path) -> None:
        self.corpus = corpus
        self.cases: list[dict[str, Any]] = []
        self.copied: dict[str, str] = {}  # original folder -> its copy

    def _stable(self, p: Path) -> bool:
        s = str(p.resolve())
        return s.startswith(str(SHARED.resolve())) or s.startswith(str((ROOT / "tests" / "data").resolve()))

    def path(self, p: Any) -> str:
        """The path to use later for ``p``: itself (committed or shared data) or a copy of its
        folder."""
        p = Path(p)
        if not p.exists() or self._stable(p):
            return str(p.resolve()) if p.exists() else str(p)
        folder = (p if p.is_dir() else p.parent).resolve()
        key = str(folder)
        if key not in self.copied:
            dst = self.corpus / "files" / f"{len(self.copied):05d}"
            shutil.copytree(folder, dst, symlinks=True,
                            ignore=shutil.ignore_patterns("*.aveas", "*.aveas.zip"))
            self.copied[key] = str(dst)
        return str(Path(self.copied[key]) / p.resolve().relative_to(folder))

    def options(self, v: Any) -> Any:
        if isinstance(v, dict):
            return {k: self.options(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [self.options(x) for x in v]
        if isinstance(v, str) and ("/" in v) and Path(v).exists():
            return self.path(v)
        return v

    def record(self, conv, inputs, map_source, options) -> None:
        if conv.direction != "import" or conv.name == "openlabel":
            return
        k = len(self.cases)
        if isinstance(map_source, (bytes, bytearray)) or (
                isinstance(map_source, str) and map_source.lstrip().startswith("<")):
            data = map_source if isinstance(map_source, (bytes, bytearray)) else map_source.encode()
            mp = self.corpus / "maps" / f"{k:05d}.xodr"
            mp.parent.mkdir(parents=True, exist_ok=True)
            mp.write_bytes(bytes(data))
            map_s: str | None = str(mp)
        else:
            map_s = None if map_source is None else self.path(map_source)
        if hasattr(options, "model_dump"):
            opts = options.model_dump(mode="json", exclude_unset=True)
        else:
            opts = dict(options or {})
        self.cases.append({"converter": conv.name, "inputs": [self.path(p) for p in inputs],
                           "map": map_s, "options": self.options(opts), "crs": None})

    def save(self) -> None:
        (self.corpus / "cases.json").write_text(json.dumps(self.cases, indent=1))


_REC: _Recorder | None = None


def pytest_configure(config) -> None:
    """Record every importer call (``AVEAS_CORPUS`` names the corpus folder)."""
    global _REC
    corpus = os.environ.get("AVEAS_CORPUS")
    if not corpus:
        return
    from aveas_format.converters.registry import Converter

    _REC = _Recorder(Path(corpus))
    original = Converter.__call__

    def call(self, *args, options=None, **kw):
        try:
            _REC.record(self, list(args[0]) if args else list(kw.get("inputs", [])),
                        kw.get("map_source"), options)
        except Exception as e:  # noqa: BLE001 - a case that cannot be recorded is left out
            print(f"compare_conversions: not recorded: {self.name}: {e}", file=sys.stderr)
        return original(self, *args, options=options, **kw)

    Converter.__call__ = call


def pytest_unconfigure(config) -> None:
    if _REC is not None:
        _REC.save()


def capture(corpus: Path, pytest_args: list[str]) -> int:
    corpus.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "AVEAS_CORPUS": str(corpus), "PYTHONPATH": f"{ROOT}:{ROOT / 'tools'}"}
    rc = subprocess.call([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", "0",
                          "-p", "compare_conversions", *(pytest_args or TESTS)], cwd=ROOT, env=env)
    cases = json.loads((corpus / "cases.json").read_text()) if (corpus / "cases.json").exists() else []
    for name, inputs, map_, opts, crs in REAL:
        o = {k: ([str(SHARED / x) for x in v] if k == "vtypes" else v) for k, v in opts.items()}
        cases.append({"converter": name, "inputs": [str(SHARED / p) for p in inputs],
                      "map": None if map_ is None else str(SHARED / map_), "options": o, "crs": crs})
    (corpus / "cases.json").write_text(json.dumps(cases, indent=1))
    print(f"{len(cases)} cases in {corpus / 'cases.json'} (pytest exit {rc})")
    return 0


# --- run -------------------------------------------------------------------------------------------

def _run_cases(corpus: Path, out: Path) -> None:
    """(In the subprocess of one tree.) Convert every case of the corpus into ``out``."""
    import warnings

    from aveas_format.converters.registry import convert
    from aveas_format.errors import collect_source_findings

    cases = json.loads((corpus / "cases.json").read_text())
    for k, c in enumerate(cases):
        d = out / f"{k:04d}"
        d.mkdir(parents=True, exist_ok=True)
        said: dict[str, list] = {"warnings": [], "findings": []}
        with collect_source_findings() as found, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                rec = convert(c["converter"], c["inputs"], map_source=c["map"],
                              options=c["options"], crs=c["crs"])
                rec.write(d / "rec.aveas")
            except Exception as e:  # noqa: BLE001 - the error is the outcome to compare
                (d / "error.json").write_text(json.dumps({"type": type(e).__name__, "message": str(e)}))
        said["warnings"] = sorted({str(w.message) for w in caught
                                   if not issubclass(w.category, DeprecationWarning)})
        said["findings"] = sorted(json.dumps([f.code, f.message, f.location], sort_keys=True,
                                             default=str) for f in found)
        (d / "said.json").write_text(json.dumps(said, indent=1))
    print(f"{len(cases)} cases converted into {out}")


def run(tree: Path, corpus: Path, out: Path) -> int:
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    env = {**os.environ, "PYTHONPATH": str(tree.resolve())}
    code = (f"import sys; sys.path.insert(0, {str(ROOT / 'tools')!r}); import compare_conversions as c; "
            f"c._run_cases(c.Path({str(corpus.resolve())!r}), c.Path({str(out.resolve())!r}))")
    return subprocess.call([sys.executable, "-c", code], env=env, cwd=str(out))


# --- compare ---------------------------------------------------------------------------------------

def _tables(d: Path) -> dict[str, Any]:
    import pyarrow.parquet as pq

    return {str(p.relative_to(d)): pq.read_table(p) for p in sorted(d.rglob("*.parquet"))}


def _meta(d: Path) -> dict[str, Any]:
    m = json.loads((d / "recording.json").read_text())
    m.pop("recording_id", None)
    return m


def compare(a: Path, b: Path) -> int:
    diffs: list[str] = []
    cases = sorted(p.name for p in a.iterdir() if p.is_dir())
    n_rec = n_err = 0
    for k in cases:
        da, db = a / k, b / k
        ea, eb = (json.loads((d / "error.json").read_text()) if (d / "error.json").exists() else None
                  for d in (da, db))
        if ea != eb:
            diffs.append(f"{k}: outcome differs: {ea or 'a recording'} vs {eb or 'a recording'}")
            continue
        sa, sb = (json.loads((d / "said.json").read_text()) for d in (da, db))
        if sa != sb:
            diffs.append(f"{k}: warnings/findings differ: {sa} vs {sb}")
        if ea is not None:
            n_err += 1
            continue
        n_rec += 1
        ra, rb = da / "rec.aveas", db / "rec.aveas"
        ta, tb = _tables(ra), _tables(rb)
        if set(ta) != set(tb):
            diffs.append(f"{k}: tables differ: {sorted(ta)} vs {sorted(tb)}")
        for name in sorted(set(ta) & set(tb)):
            x, y = ta[name], tb[name]
            if not x.schema.equals(y.schema, check_metadata=True):
                diffs.append(f"{k}: {name}: schema differs:\n{x.schema}\nvs\n{y.schema}")
            elif not x.equals(y):
                cols = [c for c in x.column_names if not x.column(c).equals(y.column(c))]
                diffs.append(f"{k}: {name}: values differ in {cols}")
        if _meta(ra) != _meta(rb):
            ma, mb = _meta(ra), _meta(rb)
            keys = sorted(q for q in set(ma) | set(mb) if ma.get(q) != mb.get(q))
            diffs.append(f"{k}: recording.json differs in {keys}: "
                         + "; ".join(f"{q}: {ma.get(q)!r} vs {mb.get(q)!r}" for q in keys)[:2000])
        if (ra / "map.xodr").read_bytes() != (rb / "map.xodr").read_bytes():
            diffs.append(f"{k}: map.xodr differs")
    for line in diffs:
        print(line)
    print(f"{len(cases)} cases: {n_rec} recordings and {n_err} errors compared; "
          f"{len(diffs)} difference(s)")
    return 1 if diffs else 0


def main(argv: list[str]) -> int:
    if not argv or argv[0] not in ("capture", "run", "compare"):
        print(__doc__)
        return 2
    step, rest = argv[0], argv[1:]
    if step == "capture":
        return capture(Path(rest[0]), rest[1:])
    if step == "run":
        return run(Path(rest[0]), Path(rest[1]), Path(rest[2]))
    return compare(Path(rest[0]), Path(rest[1]))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
