"""Run a :class:`~aveas_format.sim.scenario.Scenario` with Eclipse SUMO.

>>> from aveas_format.sim import Scenario, simulate
>>> res = simulate(Scenario(duration=600), recording=True)          # doctest: +SKIP
>>> res.recording.write("sim.aveas"); res.mean_speeds()["car"]     # doctest: +SKIP

Each run happens in its own temporary directory: ``netconvert`` builds the network (from the
highway builder's OpenDRIVE or a given map; once per process and network, :func:`prepare_network`),
the routes are written from the scenario, ``sumo`` runs with FCD output (Parquet where the binary
supports it), and the FCD is read back. With ``recording=True`` the FCD goes through the
``sumo-fcd`` converter into a recording on the same OpenDRIVE map (so simulated data is in the
format and validates like recorded data). With ``fcd=False`` (what the fitter's mean-speed metric
uses) SUMO writes only the crossings of the measurement section's entry and exit.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np
import pyarrow as pa

from aveas_format.errors import AveasError
from aveas_format.sim.scenario import Network, Scenario

INSTALL_HINT = 'install Eclipse SUMO: pip install "aveas-format[sim]" (or set SUMO_HOME)'


class SumoNotFoundError(AveasError):
    """The ``sumo``/``netconvert`` binaries cannot be found."""


class SimulationError(AveasError):
    """A SUMO tool failed; the message carries the tail of its log."""


@lru_cache(maxsize=8)
def find_sumo(tool: str = "sumo") -> Path:
    """The path of a SUMO binary: ``$SUMO_HOME/bin``, the ``eclipse-sumo`` wheel, then ``PATH``."""
    candidates: list[Path] = []
    if os.environ.get("SUMO_HOME"):
        candidates.append(Path(os.environ["SUMO_HOME"]) / "bin" / tool)
    try:
        import sumo  # the eclipse-sumo wheel

        candidates.append(Path(sumo.SUMO_HOME) / "bin" / tool)
    except (ImportError, AttributeError):
        pass
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    w = shutil.which(tool)
    if w:
        return Path(w)
    raise SumoNotFoundError(f"SUMO's {tool!r} binary was not found; {INSTALL_HINT}")


def _sumo_env(binary: Path) -> dict[str, str]:
    env = dict(os.environ)
    home = binary.resolve().parent.parent
    if "SUMO_HOME" not in env and (home / "data").is_dir():
        env["SUMO_HOME"] = str(home)  # silences the XML-validation warning
    return env


@lru_cache(maxsize=4)
def _supports_parquet(binary: Path) -> bool:
    try:
        v = subprocess.run([str(binary), "--version"], capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return False
    return "Parquet" in v.stdout


def run_tool(cmd: list[str], cwd: Path, log: Path, what: str, timeout: float | None) -> None:
    """Run a SUMO tool (``cmd``) in ``cwd``, its output appended to ``log``; a failure or a timeout
    is a :class:`SimulationError` naming ``what`` and the log's last lines."""
    try:
        with open(log, "ab") as f:
            p = subprocess.run(cmd, cwd=cwd, stdout=f, stderr=subprocess.STDOUT, timeout=timeout,
                               env=_sumo_env(Path(cmd[0])))
    except subprocess.TimeoutExpired:
        raise SimulationError(f"{what} ran longer than {timeout} s; log tail:\n{_tail(log)}") from None
    except OSError as e:
        raise SimulationError(f"cannot run {what}: {e}") from None
    if p.returncode != 0:
        raise SimulationError(f"{what} failed (exit {p.returncode}); log tail:\n{_tail(log)}")


def _tail(log: Path, n: int = 20) -> str:
    try:
        return "\n".join(log.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"


@dataclass
class NetInfo:
    """A built SUMO network: the ``.net.xml`` and OpenDRIVE bytes (picklable, so a fit builds it
    once and ships it to every worker), the departure and arrival edges, the measurement section
    and each edge's lanes as ``(lane id, length)``."""

    net_file: Path
    xodr: bytes
    from_edge: str
    to_edge: str
    measure_edges: list[str] | None
    measure_pos: tuple[float, float] | None
    net_xml: bytes = b""
    lanes: dict[str, list[tuple[str, float]]] = field(default_factory=dict)

    def write(self, workdir: Path) -> NetInfo:
        """Write ``net.net.xml`` and ``map.xodr`` into ``workdir``; the copy that points there."""
        (workdir / "net.net.xml").write_bytes(self.net_xml)
        (workdir / "map.xodr").write_bytes(self.xodr)
        return replace(self, net_file=workdir / "net.net.xml")

    def section(self) -> tuple[str, float, float] | None:
        """``(edge, entry, exit)`` when the measurement section is a position range on one edge,
        which two cross-sections delimit (the built highway's); else None."""
        if not self.measure_edges or len(self.measure_edges) != 1 or self.measure_pos is None:
            return None
        edge = self.measure_edges[0]
        lengths = [length for _, length in self.lanes.get(edge, [])]
        if not lengths:
            return None
        lo, hi = self.measure_pos
        hi = min(hi, min(lengths) - _EXIT_MARGIN)
        return (edge, float(lo), float(hi)) if 0 < lo < hi else None


#: the exit cross-section sits this far before the edge's end when the section reaches it (a
#: vehicle arrives, and leaves the network, when its front reaches the end)
_EXIT_MARGIN = 0.1


def _map_bytes(path: Path) -> bytes:
    if path.suffix == ".xodr":
        return path.read_bytes()
    from aveas_format.io.reader import open_recording

    rec = open_recording(path)
    if rec.map_source is None:
        raise AveasError("the recording has no map", path=path)
    return rec.map_source


_NET_CACHE: dict[str, NetInfo] = {}


def prepare_network(net: Network, *, timeout: float | None = 120) -> NetInfo:
    """OpenDRIVE (built or given) -> SUMO network with lane speeds and lane bans applied, in memory.

    ``netconvert`` runs once per process and network (cached by the network settings and the map
    file's mtime); a fit calls this once and passes the result to every evaluation."""
    key = net.model_dump_json()
    if net.map is not None and Path(net.map).exists():
        key += str(Path(net.map).stat().st_mtime_ns)
    if key not in _NET_CACHE:
        tmp = Path(tempfile.mkdtemp(prefix="aveas-net-"))
        try:
            info = _build_network(net, tmp, timeout)
            info = replace(info, net_xml=info.net_file.read_bytes(), net_file=Path("net.net.xml"))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        if len(_NET_CACHE) > 16:
            _NET_CACHE.clear()
        _NET_CACHE[key] = info
    return _NET_CACHE[key]


def build_network(net: Network, workdir: Path, *, timeout: float | None = 120) -> NetInfo:
    """:func:`prepare_network`, written into ``workdir`` (``net.net.xml``, ``map.xodr``)."""
    return prepare_network(net, timeout=timeout).write(workdir)


def _build_network(net: Network, workdir: Path, timeout: float | None) -> NetInfo:
    from lxml import etree

    if net.map is None:
        from aveas_format.opendrive.builder import straight_highway

        xodr = straight_highway(length=net.inflow + net.length, lanes_right=net.lanes,
                                lane_width=net.lane_width, name="sim_highway",
                                geo_reference=net.geo_reference).encode()
    else:
        xodr = _map_bytes(Path(net.map))
    (workdir / "map.xodr").write_bytes(xodr)
    log = workdir / "netconvert.log"
    run_tool([str(find_sumo("netconvert")), "--opendrive-files", "map.xodr", "-o", "net.net.xml",
          "--no-warnings"], workdir, log, "netconvert", timeout)
    path = workdir / "net.net.xml"
    tree = etree.parse(str(path))
    speed = f"{net.lane_speed_kmh / 3.6:.4f}"
    edges = [e for e in tree.iter("edge") if e.get("function") != "internal"]
    for e in edges:
        lanes = e.findall("lane")
        for ln in lanes:
            ln.set("speed", speed)
        for vclass, n in net.ban_left_lanes.items():
            for ln in lanes[len(lanes) - n:] if n < len(lanes) else []:
                dis = (ln.get("disallow") or "").split()
                if vclass not in dis:
                    ln.set("disallow", " ".join([*dis, vclass]))
                if ln.get("allow"):
                    ln.set("allow", " ".join(c for c in ln.get("allow").split() if c != vclass))
    for e in tree.iter("lane"):  # internal lanes too
        e.set("speed", speed)
    tree.write(str(path), xml_declaration=True, encoding="UTF-8")
    ids = [e.get("id") for e in edges]
    lanes = {e.get("id"): [(ln.get("id"), float(ln.get("length"))) for ln in e.findall("lane")]
             for e in edges}
    if net.map is None:
        edge = next((i for i in ids if i.startswith("-")), ids[0])
        return NetInfo(path, xodr, net.from_edge or edge, net.to_edge or edge,
                       net.measure_edges or [edge], net.measure_pos or (net.inflow, net.inflow + net.length),
                       lanes=lanes)
    froms = {e.get("from") for e in edges}
    tos = {e.get("to") for e in edges}
    sources = [e.get("id") for e in edges if e.get("from") not in tos]
    sinks = [e.get("id") for e in edges if e.get("to") not in froms]
    fe, te = net.from_edge, net.to_edge
    if fe is None:
        if len(sources) != 1:
            raise AveasError(f"cannot choose the departure edge among {sources or ids}: set "
                             "network.from_edge (and to_edge)")
        fe = sources[0]
    if te is None:
        if len(sinks) != 1:
            raise AveasError(f"cannot choose the arrival edge among {sinks or ids}: set network.to_edge")
        te = sinks[0]
    return NetInfo(path, xodr, fe, te, net.measure_edges, net.measure_pos, lanes=lanes)


@dataclass
class SimResult:
    """The outcome of one run: the FCD (columns id, type, speed [m/s], edge, pos, time), or with
    ``fcd=False`` only the measurement-section crossings (``section``: id, type, t_in, t_out), and
    when asked for the recording and the per-vehicle speed factors. ``timings`` (s): ``network``,
    ``routes``, ``sumo`` (the SUMO process), ``read`` (reading its output), ``recording``."""

    scenario: Scenario
    fcd: pa.Table | None
    net: NetInfo
    runtime_s: float
    log: str = ""
    recording: object | None = None
    speed_factors: dict[str, float] = field(default_factory=dict)
    section: pa.Table | None = None
    timings: dict[str, float] = field(default_factory=dict)

    def mean_speeds(self, *, min_samples: int = 2) -> dict[str, np.ndarray]:
        """Per class (vType id): each vehicle's mean speed (km/h) on the measurement section:
        section length / time between the entry and exit cross-sections when SUMO wrote the
        crossings, else the mean of its FCD speed samples there (the same quantity: the time mean
        of the speed over the section)."""
        classes = [c.name for c in self.scenario.classes]
        if self.section is not None:
            return section_mean_speeds(self.section, self.net.section(), classes)
        return fcd_mean_speeds(self.fcd, self.net.measure_edges, self.net.measure_pos, classes,
                               min_samples=min_samples)


def section_mean_speeds(crossings: pa.Table, section: tuple[str, float, float], classes: list[str]
                        ) -> dict[str, np.ndarray]:
    """Per class: (exit - entry) / (t_out - t_in) in km/h of every vehicle that crossed both."""
    _, lo, hi = section
    dt = (crossings["t_out"].to_numpy(zero_copy_only=False)
          - crossings["t_in"].to_numpy(zero_copy_only=False))
    types = crossings["type"].to_numpy(zero_copy_only=False)
    ok = np.isfinite(dt) & (dt > 0)
    v = np.full(len(dt), np.nan)
    v[ok] = (hi - lo) / dt[ok] * 3.6
    return {c: v[ok & (types == c)] for c in classes}


def fcd_mean_speeds(fcd: pa.Table, edges: list[str] | None, pos: tuple[float, float] | None,
                    classes: list[str], *, min_samples: int = 2) -> dict[str, np.ndarray]:
    import pyarrow.compute as pc

    mask = pc.is_valid(fcd["id"])
    if edges is not None:
        mask = pc.and_(mask, pc.is_in(fcd["edge"], pa.array(edges)))
    if pos is not None:
        mask = pc.and_(mask, pc.and_(pc.greater_equal(fcd["pos"], pos[0]), pc.less_equal(fcd["pos"], pos[1])))
    t = fcd.filter(mask)
    ids = t["id"].to_numpy(zero_copy_only=False)
    speed = t["speed"].to_numpy(zero_copy_only=False).astype(np.float64) * 3.6
    types = t["type"].to_numpy(zero_copy_only=False)
    out: dict[str, np.ndarray] = {}
    if len(ids) == 0:
        return {c: np.empty(0) for c in classes}
    uniq, inv, counts = np.unique(ids, return_inverse=True, return_counts=True)
    sums = np.bincount(inv, weights=speed)
    first = np.zeros(len(uniq), dtype=np.int64)
    first[inv[::-1]] = np.arange(len(inv))[::-1]
    vt = types[first]
    ok = counts >= min_samples
    means = sums / counts
    for c in classes:
        out[c] = means[ok & (vt == c)]
    return out


def simulate(scenario: Scenario, *, recording: bool = False, speed_factors: bool = False,
             fcd: bool = True, network: NetInfo | None = None, workdir: str | Path | None = None,
             timeout: float | None = 600, recording_options: dict | None = None) -> SimResult:
    """Run ``scenario``; see the module docstring. ``workdir`` keeps the files (default: a
    temporary directory, removed afterwards). ``recording_options``: options of the ``sumo-fcd``
    import that makes the recording (its metadata: ``license``, ``partner``, ``title``, ...;
    without a ``license`` the recording carries the stand-in the validator flags).

    ``fcd=False`` has SUMO write only what the per-vehicle mean speeds need: the crossings of two
    instant induction loops per lane at the ends of the measurement section when it is a position
    range on one edge (:meth:`NetInfo.section`), else the FCD of the measurement edges only.
    ``network``: a :func:`prepare_network` result to reuse (default: built, or taken from this
    process's cache)."""
    if recording and not fcd:
        raise ValueError("a recording needs the FCD (fcd=True)")
    sumo = find_sumo("sumo")
    tmp = None
    if workdir is None:
        tmp = tempfile.mkdtemp(prefix="aveas-sim-")
        wd = Path(tmp)
    else:
        wd = Path(workdir)
        wd.mkdir(parents=True, exist_ok=True)
    try:
        timings: dict[str, float] = {}
        t0 = time.perf_counter()
        net = (network or prepare_network(scenario.network, timeout=timeout)).write(wd)
        t1 = time.perf_counter()
        timings["network"] = t1 - t0
        (wd / "routes.rou.xml").write_text(scenario.routes_xml(net.from_edge, net.to_edge))
        t2 = time.perf_counter()
        timings["routes"] = t2 - t1
        cmd = [str(sumo), "-n", "net.net.xml", "-r", "routes.rou.xml", "--step-length",
               f"{scenario.step_length:g}", "--seed", str(scenario.seed), "--no-step-log", "true",
               "--duration-log.statistics", "true", "--log", "sumo.log"]
        section = None if fcd else net.section()
        fcd_name = None
        if section is not None:
            (wd / "section.add.xml").write_text(_section_loops_xml(net, section))
            cmd += ["--additional-files", "section.add.xml"]
        else:
            fcd_name = "fcd.parquet" if _supports_parquet(sumo) else "fcd.xml"
            attrs = "id,type,speed,lane,pos" + (",x,y,angle" if recording else "")
            cmd += ["--fcd-output", fcd_name, "--fcd-output.attributes", attrs]
            if not fcd and net.measure_edges:
                (wd / "section.edges.txt").write_text("".join(f"edge:{e}\n" for e in net.measure_edges))
                cmd += ["--fcd-output.filter-edges.input-file", "section.edges.txt"]
        if scenario.lane_change_duration > 0:
            cmd += ["--lanechange.duration", f"{scenario.lane_change_duration:g}"]
        if scenario.fcd_period and fcd_name:
            cmd += ["--device.fcd.period", f"{scenario.fcd_period:g}"]
        if not scenario.drain:
            cmd += ["--end", f"{scenario.duration:g}"]
        if speed_factors:
            cmd += ["--vehroute-output", "vehroutes.xml", "--vehroute-output.speedfactor", "true"]
        cmd += scenario.extra_args
        run_tool(cmd, wd, wd / "sumo.stdout.log", "sumo", timeout)
        t3 = time.perf_counter()
        timings["sumo"] = t3 - t2
        runtime = t3 - t0
        crossings = _read_section(wd / "section.xml") if section is not None else None
        table = _read_fcd(wd / fcd_name) if fcd_name else None
        log = (wd / "sumo.log").read_text(errors="replace") if (wd / "sumo.log").exists() else ""
        res = SimResult(scenario, table, net, runtime, log, section=crossings, timings=timings)
        if speed_factors:
            res.speed_factors = _read_speed_factors(wd / "vehroutes.xml")
        t4 = time.perf_counter()
        timings["read"] = t4 - t3
        if recording:
            from aveas_format.converters import convert

            res.recording = convert("sumo-fcd", [wd / fcd_name], map_source=net.xodr, options={
                "partner": "aveas-format sim", "title": "SUMO simulation", **(recording_options or {}),
                "net_file": str(net.net_file), "vtypes": [str(wd / "routes.rou.xml")]})
            timings["recording"] = time.perf_counter() - t4
        res.net = replace(net, net_file=Path("net.net.xml"))
        return res
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _section_loops_xml(net: NetInfo, section: tuple[str, float, float]) -> str:
    """Instant induction loops on every lane of the section's edge at its entry and exit."""
    edge, lo, hi = section
    lines = ["<additional>"]
    for k, (lane, _) in enumerate(net.lanes[edge]):
        for kind, pos in (("in", lo), ("out", hi)):
            lines.append(f'    <instantInductionLoop id="{kind}_{k}" lane={quoteattr(lane)} '
                         f'pos="{pos:.3f}" file="section.xml"/>')
    lines.append("</additional>")
    return "\n".join(lines) + "\n"


def _read_section(path: Path) -> pa.Table:
    """The section crossings: per vehicle the first entry and the first exit (a vehicle in the
    middle of a lane change may be seen on two lanes)."""
    if not path.exists():
        raise SimulationError("sumo wrote no section output", path=path)
    from aveas_format.safeio import iterparse

    t_in: dict[str, float] = {}
    t_out: dict[str, float] = {}
    vtype: dict[str, str] = {}
    for _, el in iterparse(str(path), tag="instantOut"):
        if el.get("state") == "enter":
            vid = el.get("vehID")
            (t_in if el.get("id", "").startswith("in_") else t_out).setdefault(vid, float(el.get("time")))
            vtype.setdefault(vid, el.get("type"))
        el.clear()
    ids = list(vtype)
    return pa.table({"id": pa.array(ids, pa.string()), "type": pa.array([vtype[i] for i in ids], pa.string()),
                     "t_in": pa.array([t_in.get(i, np.nan) for i in ids], pa.float64()),
                     "t_out": pa.array([t_out.get(i, np.nan) for i in ids], pa.float64())})


def _read_fcd(path: Path) -> pa.Table:
    if not path.exists():
        raise SimulationError("sumo wrote no FCD output", path=path)
    if path.suffix == ".parquet":
        import pyarrow.parquet as pq

        t = pq.read_table(path)
        t = t.filter(pa.compute.is_valid(t["vehicle_id"]))
        cols = {"time": t["timestep_time"], "id": t["vehicle_id"], "type": t["vehicle_type"],
                "speed": t["vehicle_speed"], "pos": t["vehicle_pos"],
                "edge": pa.compute.replace_substring_regex(t["vehicle_lane"].cast(pa.string()),
                                                           r"_\d+$", "")}
        return pa.table(cols)
    from aveas_format.safeio import iterparse

    rows: dict[str, list] = {k: [] for k in ("time", "id", "type", "speed", "pos", "edge")}
    time_ = 0.0
    for _, el in iterparse(str(path), events=("start",), tag=("timestep", "vehicle")):
        if el.tag == "timestep":
            time_ = float(el.get("time"))
            continue
        rows["time"].append(time_)
        rows["id"].append(el.get("id"))
        rows["type"].append(el.get("type"))
        rows["speed"].append(float(el.get("speed")))
        rows["pos"].append(float(el.get("pos")))
        rows["edge"].append(_edge(el.get("lane")))
    return pa.table(rows)


_LANE = re.compile(r"_\d+$")


@lru_cache(maxsize=4096)
def _edge(lane: str | None) -> str | None:
    return None if lane is None else _LANE.sub("", lane)


def _read_speed_factors(path: Path) -> dict[str, float]:
    from aveas_format.safeio import iterparse

    out = {}
    for _, el in iterparse(str(path), tag="vehicle"):
        if el.get("speedFactor") is not None:
            out[el.get("id")] = float(el.get("speedFactor"))
    return out
