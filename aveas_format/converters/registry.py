"""The converter registry: one module per foreign format, registered by name.

A converter is a function ``(inputs, *, map_source, options) -> Recording`` decorated with
:func:`converter`, which declares its name, direction, the acquisition method it produces, file
patterns, a pydantic options model and a one-line description. ``aveas-format convert --from NAME``
finds it here; ``aveas-format convert --list`` prints the table.

Exporters (recording -> foreign format) register with ``direction="export"`` and have the signature
``(recording, output, *, options) -> list[Path]``. Its companion files count as outputs: the CLI
refuses to replace any of them without ``--overwrite`` (:meth:`Converter.outputs`). The map next
to the output (options ``write_map``/``map_file``, ``converters.common.companion.companion_map_path``) is
counted by default; an exporter that writes other files next to its output declares them with
``outputs=``. An exporter that reads the states itself, part by part from the recording's file
when given a recording opened without them (``open_recording(path, states=False)``), declares
``streams_states=True``: the CLI's ``export`` then opens the recording so (bounded memory).
An importer that can write the recording itself, its states in parts (bounded memory), declares
``writes=FUNCTION`` (``(inputs, output, *, map_source, options, overwrite)``): :func:`convert_to`
and the CLI's ``convert`` of one recording call it.

The recording.json values only a person can state (:data:`ASKED`: partner, start time, licence)
follow one rule for every importer: where neither the source nor the options state one, the
recording gets a stand-in ("unknown", 1970-01-01, "unspecified"; the validator warns about each,
it breaks no MUST of the format) and the import says so in one warning that names every missing
value and the ``-O KEY=VALUE`` that states it (:class:`UnstatedWarning`, after the import, when
the recording's values are known: a source may carry them, as this toolkit's exports do). An
importer declares which of them its source can carry, ``provides=("start_time",)``
(:meth:`Converter.unstated`: those the CLI of a simulation asks for).

An importer declares how to recognise its files: ``patterns`` (file name globs) and ``sniff``,
either byte strings of which one occurs in the file's first :data:`SNIFF_BYTES` bytes, or a
function ``(path, first bytes) -> bool`` (it may read the file's header, e.g. a Parquet schema, and
returns False for what it cannot read). :func:`importers_for` gives the importers of a file: those
whose patterns match its name and, where several do, those whose ``sniff`` recognises it (all of
them where none does). ``aveas-format validate FILE`` and ``aveas_format.validate(FILE)`` take a
submitted file this way (:mod:`aveas_format.validate.submission`), partner converters included.

A converter whose source needs an optional stack declares it: ``requires=("mcap", ...)`` (modules)
and ``extra="ros2"``; calling it without them is a one-line
:class:`~aveas_format.errors.MissingDependencyError` naming the extra, and ``convert --list`` says
which extra a converter needs. An unknown name or option is a
:class:`~aveas_format.errors.UsageError` with the closest known name.

:func:`load_converters` imports the converter modules of this package and of installed partner
packages (entry-point group ``aveas_format.converters``) through :mod:`aveas_format.plugins`.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError

from aveas_format import plugins
from aveas_format.errors import AveasError, MissingCrsError, UsageError, did_you_mean, require


class ConverterOptions(BaseModel):
    """Base of every converter's options: unknown options are errors. A docstring under a field
    is its description (shown in docs/converters.md). A number given for a text option (an id
    ``1`` in an options file or the API) is its text; the CLI's ``-O KEY=VALUE`` reads every
    value by its field's type (:func:`aveas_format.cli.options.coerce_option`)."""

    model_config = ConfigDict(extra="forbid", use_attribute_docstrings=True,
                              coerce_numbers_to_str=True)


class ImportOptions(ConverterOptions):
    """Options every importer takes: recording metadata the source files may not carry."""

    partner: str | None = None
    """Institution that acquired the data (recording.json acquisition.partner)."""
    start_time: str | None = None
    """UTC ISO 8601 time of `time` = 0, where the source has no absolute time."""
    recording_id: str | None = None
    """Recording id (default: a new UUID)."""
    title: str | None = None
    """Recording title."""
    license: str = "unspecified"
    """Licence of the data (recording.json rights.license)."""
    owner: str | None = None
    """Owner of the data (default: the partner)."""
    right_of_use: str = "research_only"
    """research_only or commercial."""
    #: False where a converter's own ``crs`` option means its source's CRS (rotated boxes: the
    #: world file's), which it projects into the map's frame itself
    crs_is_recording_crs: ClassVar[bool] = True
    crs: str | None = None
    """The recording's CRS (PROJ, EPSG or WKT) where the map has no ``<geoReference>`` (it alone
    then defines the frame, FORMAT.md); CLI ``--crs``, API ``convert(..., crs=)``. Must agree with
    the map's geoReference where there is one."""


#: a declaration of how an importer recognises its files: byte strings of which one occurs in the
#: file's first bytes, or a function of the path and those bytes
Sniff = tuple[bytes, ...] | Callable[[Path, bytes], bool]
#: bytes read from the start of a file to sniff it
SNIFF_BYTES = 1 << 16

#: recording.json values only a person can state (the import options of the same names)
ASKED = ("partner", "start_time", "license")
#: each of :data:`ASKED`: what it is, how to state it
ASK_HOW = {"partner": ("the partner", "partner=INSTITUTION"),
           "start_time": ("the start time", "start_time=2024-05-13T08:15:00Z (UTC of time 0)"),
           "license": ("the licence", "license=LICENCE (an SPDX id, e.g. CC-BY-4.0)")}


class UnstatedWarning(UserWarning):
    """An import wrote a stand-in for a value only a person can state (:data:`ASKED`)."""


def unstated_note(name: str, missing: list[str]) -> str:
    """``converter NAME: its source does not state the partner and the licence; pass -O
    partner=INSTITUTION -O license=...`` for the values of :data:`ASKED` in ``missing``."""
    what = [ASK_HOW[k][0] for k in missing]
    what_text = ", ".join(what[:-1]) + " and " + what[-1] if len(what) > 1 else what[0]
    return (f"converter {name}: its source does not state {what_text}; pass "
            + " ".join(f"-O {ASK_HOW[k][1]}" for k in missing)
            + " (or put them in --options FILE.json)")
#: acquisition methods of simulations: their time zero has no calendar date, start_time is not asked
SIMULATION_METHODS = ("traffic_simulation", "driving_simulator")


@dataclass(frozen=True)
class Converter:
    name: str
    direction: str  # "import" or "export"
    description: str
    patterns: tuple[str, ...]
    method: str | None  # acquisition method of the recordings an importer produces
    options: type[ConverterOptions]
    fn: Callable[..., Any]
    needs_map: bool = True
    version: str = "1"
    #: modules of an optional dependency the converter needs, and the extra that installs them
    requires: tuple[str, ...] = ()
    extra: str | None = None
    #: an exporter's files for an output and its options (default: the output alone)
    outputs_fn: Callable[[Path, Any], list[Path]] | None = None
    #: which of :data:`ASKED` the source can carry (an importer)
    provides: tuple[str, ...] = ()
    #: an exporter that reads the states itself from a recording opened without them
    #: (``open_recording(path, states=False)``), in bounded memory: the CLI opens it so
    streams_states: bool = False
    #: an importer that writes the recording itself: ``(inputs, output, *, map_source, options,
    #: overwrite) -> (the recording as written, its states, those on the map)`` (its states not
    #: loaded where they were written in parts)
    writes: Callable[..., Any] | None = None
    #: how an importer recognises its files beyond ``patterns`` (see the module docstring)
    sniff: Sniff | None = None
    #: what to try when an import lands mostly off its map (:class:`~aveas_format.mapref.offmap.
    #: OffMapWarning`), after the general hint (the map, the CRS)
    off_map_hint: str = ""

    def matches(self, path: Path) -> bool:
        """Whether ``path``'s name matches one of the file patterns."""
        name = Path(path).name.lower()
        return any(fnmatch.fnmatch(name, pat.lower()) for pat in self.patterns)

    def recognises(self, path: Path, head: bytes) -> bool | None:
        """Whether the file's first bytes ``head`` are of this importer's format (its ``sniff``);
        None where it declares no ``sniff``."""
        if self.sniff is None:
            return None
        if callable(self.sniff):
            return bool(self.sniff(Path(path), head))
        return any(sig in head for sig in self.sniff)

    def unstated(self, options: dict[str, Any] | None) -> list[str]:
        """The values of :data:`ASKED` that neither the source can carry nor ``options`` give: an
        importer would write a stand-in for them ("unknown", 1970-01-01, "unspecified") that the
        validator flags. A simulation's start time is not asked (it has no calendar date)."""
        if self.direction != "import":
            return []
        given = {k for k, v in (options or {}).items() if v not in (None, "")}
        return [k for k in ASKED if k not in given and k not in self.provides
                and not (k == "start_time" and self.method in SIMULATION_METHODS)]

    @property
    def available(self) -> bool:
        """Whether the optional dependencies of :attr:`requires` are installed."""
        import importlib.util

        def found(module: str) -> bool:
            try:
                return importlib.util.find_spec(module) is not None
            except (ImportError, ValueError):  # a missing parent package
                return False

        return all(found(m) for m in self.requires)

    def parse_options(self, raw: dict[str, Any] | None) -> ConverterOptions:
        try:
            return self.options.model_validate(raw or {})
        except ValidationError as e:
            fields = list(self.options.model_fields)
            parts = []
            for err in e.errors():
                loc = ".".join(str(p) for p in err["loc"])
                hint = did_you_mean(loc, fields) if err["type"] == "extra_forbidden" else ""
                parts.append(f"{loc}: {err['msg']}{hint}")
            raise UsageError(f"converter {self.name}: invalid options: {'; '.join(parts)} "
                             f"(options: {', '.join(fields) or 'none'})") from None

    def outputs(self, output: str | Path, options: dict[str, Any] | ConverterOptions | None = None
                ) -> list[Path]:
        """The files an export to ``output`` writes (the output and its companion files)."""
        opts = options if isinstance(options, ConverterOptions) else self.parse_options(options)
        if self.outputs_fn:
            return self.outputs_fn(Path(output), opts)
        from aveas_format.converters.common.companion import companion_map_path

        companion = companion_map_path(Path(output), opts)
        return [Path(output)] + ([companion] if companion is not None else [])

    def check_map(self, map_source: Any) -> None:
        """A :class:`~aveas_format.errors.UsageError` when the converter needs a map and has none."""
        if self.needs_map and map_source is None:
            raise UsageError(f"converter {self.name} needs a map: pass --map MAP.xodr")

    def require(self) -> None:
        """A :class:`~aveas_format.errors.MissingDependencyError` naming the extra when an
        optional dependency of the converter is not installed."""
        what = f"the {self.name} {'export' if self.direction == 'export' else 'import'}"
        for module in self.requires:
            require(module, extra=self.extra or "all", what=what)

    def __call__(self, *args: Any, options: dict[str, Any] | ConverterOptions | None = None,
                 **kw: Any) -> Any:
        opts = options if isinstance(options, ConverterOptions) else self.parse_options(options)
        self.require()
        return self.fn(*args, options=opts, **kw)


CONVERTERS: dict[str, Converter] = {}


def converter(name: str, *, description: str, patterns: tuple[str, ...] = (),
              method: str | None = None, options: type[ConverterOptions] = ConverterOptions,
              direction: str = "import", needs_map: bool = True, version: str = "1",
              requires: tuple[str, ...] = (), extra: str | None = None,
              outputs: Callable[[Path, Any], list[Path]] | None = None,
              provides: tuple[str, ...] = (), streams_states: bool = False,
              writes: Callable[..., Any] | None = None, sniff: Sniff | None = None,
              off_map_hint: str = "") -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register a converter function (decorator); ``requires``/``extra``: its optional
    dependencies, ``outputs``: an exporter's files, ``provides``: the :data:`ASKED` values its
    source carries, ``streams_states``: an exporter reads the states from the recording's file,
    ``writes``: an importer writes the recording itself, ``sniff``: how an importer recognises
    its files (see the module docstring), ``off_map_hint``: what else to try when an import
    lands mostly off its map (an option of the source's frame...)."""
    if direction not in ("import", "export"):
        raise ValueError("direction must be 'import' or 'export'")
    key = name if direction == "import" else f"{name}:export"

    def register(fn: Callable[..., Any]) -> Callable[..., Any]:
        if key in CONVERTERS:
            raise ValueError(f"converter {name!r} ({direction}) of {fn.__module__} registered twice: "
                             f"{CONVERTERS[key].fn.__module__} has it")
        CONVERTERS[key] = Converter(name=name, direction=direction, description=description,
                                    patterns=patterns, method=method, options=options, fn=fn,
                                    needs_map=needs_map, version=version, requires=requires,
                                    extra=extra, outputs_fn=outputs, provides=provides,
                                    streams_states=streams_states, writes=writes, sniff=sniff,
                                    off_map_hint=off_map_hint)
        return fn

    return register


def load_converters() -> dict[str, Converter]:
    """Every converter, built-in and of plugins (their modules register themselves on import)."""
    plugins.load("converters")
    return CONVERTERS


def get_converter(name: str, direction: str = "import") -> Converter:
    reg = load_converters()
    key = name if direction == "import" else f"{name}:export"
    if key not in reg:
        known = sorted(c.name for c in reg.values() if c.direction == direction)
        raise UsageError(f"no {direction} converter named {name!r}{did_you_mean(name, known)}; "
                         f"known: {', '.join(known)}")
    return reg[key]


def importers_for(path: str | Path) -> list[str]:
    """The importers that read files like ``path`` (sorted by name): those whose patterns match
    its name; where several do, those whose ``sniff`` recognises its first bytes (all of them
    where none does, or where the file cannot be read)."""
    path = Path(path)
    hits = sorted((c for c in load_converters().values() if c.direction == "import" and c.matches(path)),
                  key=lambda c: c.name)
    if len(hits) > 1:
        try:
            with open(path, "rb") as f:
                head = f.read(SNIFF_BYTES)
        except OSError:
            return [c.name for c in hits]
        known = [c for c in hits if c.recognises(path, head)]
        if known:
            return [c.name for c in known]
    return [c.name for c in hits]


def convert(name: str, inputs: list[str | Path], *, map_source: str | Path | bytes | None = None,
            options: dict[str, Any] | None = None, crs: str | None = None):
    """Run the importer ``name`` on ``inputs`` and return the Recording.

    ``crs`` is the recording's CRS where the map has no ``<geoReference>`` (the common import
    option ``crs``; it wins over ``options["crs"]``)."""
    return _run(name, inputs, map_source, options, crs,
                lambda conv, paths, opts: conv(paths, map_source=map_source, options=opts))


def convert_to(name: str, inputs: list[str | Path], output: str | Path, *,
               map_source: str | Path | bytes | None = None, options: dict[str, Any] | None = None,
               crs: str | None = None, overwrite: bool = False) -> tuple[Any, int, int]:
    """Run the importer ``name`` on ``inputs`` and write the recording to ``output``: ``(the
    recording as written, its states, those on the map)``. An importer that ``writes`` the
    recording itself writes its states in parts (bounded memory; the recording returned has
    them not loaded), others return a recording in memory, written here."""
    def run(conv: Converter, paths: list[Path], opts: ConverterOptions) -> tuple[Any, int, int]:
        if conv.writes is not None:
            conv.require()
            return conv.writes(paths, Path(output), map_source=map_source, options=opts,
                               overwrite=overwrite)
        rec = conv(paths, map_source=map_source, options=opts)
        rec.write(output, overwrite=overwrite)
        n = rec.states.num_rows
        return rec, n, n - rec.states.column("road_id").null_count

    return _run(name, inputs, map_source, options, crs, run)


def _run(name: str, inputs: list[str | Path], map_source: Any, options: dict[str, Any] | None,
         crs: str | None, call: Callable[[Converter, list[Path], ConverterOptions], Any]) -> Any:
    conv = get_converter(name)
    if crs is not None:
        options = {**(options or {}), "crs": crs}
    opts = conv.parse_options(options)  # usage errors first
    conv.check_map(map_source)
    paths = [Path(p) for p in inputs]
    for p in paths:
        if not p.exists():
            from aveas_format.errors import RecordingIOError

            raise RecordingIOError("input not found", path=p)
    try:
        result = call(conv, paths, opts)
    except MissingCrsError as e:
        from aveas_format.mapref.build import EXAMPLE_CRS

        cmd = (f"aveas-format convert --from {name} {' '.join(_quote(p) for p in paths)}"
               + (f" --map {_quote(map_source)}" if isinstance(map_source, (str, Path)) else "")
               + "".join(f" -O {_quote(f'{k}={v}')}" for k in ASKED
                         if (v := (options if isinstance(options, dict) else {}).get(k)) not in (None, ""))
               + f" --crs '{EXAMPLE_CRS}' -o OUT.aveas")
        raise MissingCrsError((f"{e.what}; " if getattr(e, "what", None) else "")
                              + "the map has no <geoReference>, so the recording's CRS must be given "
                              f"(API: crs=): {cmd} (a transverse Mercator at the site: put its "
                              "latitude and longitude in +lat_0/+lon_0)", path=e.path) from None
    except AveasError as e:
        if e.path is None and e.where.get("line") is not None and len(paths) == 1:
            # a located error without its file: name the (only) input
            raise type(e)(e.message, path=paths[0], **e.where) from None
        raise
    _report_stand_ins(conv, result[0] if isinstance(result, tuple) else result)
    _report_off_map(conv, result)
    return result


#: the general hint of an import mostly off its map (a converter's own follows it)
OFF_MAP_HINT = "check that --map is the map of this site and --crs the CRS of the positions"


def _report_off_map(conv: Converter, result: Any) -> None:
    """The one test of every import for positions off its map
    (:func:`aveas_format.mapref.offmap.mostly_off`, the validator's ``map.mostly_off_road``): one
    :class:`~aveas_format.mapref.offmap.OffMapWarning` with the share, the causes that would put
    the positions on the map, and what to try (:data:`OFF_MAP_HINT`, the converter's
    ``off_map_hint``). A recording written in parts (its states not loaded) is read back a row
    group at a time."""
    import warnings

    from aveas_format.mapref import offmap

    rec = result[0] if isinstance(result, tuple) else result
    found = offmap.of_recording(rec)
    if found is not None:
        warnings.warn(f"converter {conv.name}: the recording is mostly off its map: "
                      f"{found.message()}; {OFF_MAP_HINT}"
                      + (f"; {conv.off_map_hint}" if conv.off_map_hint else ""),
                      offmap.OffMapWarning, stacklevel=3)


def _report_stand_ins(conv: Converter, rec: Any) -> None:
    """The one rule for values only a person can state: one :class:`UnstatedWarning` naming
    each one the recording has only as a stand-in (neither the source nor the options state
    it), with the options that state them."""
    import warnings

    from aveas_format.converters.common.carried import stand_ins

    meta = getattr(rec, "meta", None)
    missing = stand_ins(meta) if meta is not None else []
    if missing:
        warnings.warn(unstated_note(conv.name, missing).replace(
            "; pass", ": the recording has a stand-in the validator warns about; pass"),
            UnstatedWarning, stacklevel=3)


def _quote(p: Any) -> str:
    import shlex

    return shlex.quote(str(p))
