"""The converter registry: one module per foreign format, registered by name.

A converter is a function ``(inputs, *, map_source, options) -> Recording`` decorated with
:func:`converter`, which declares its name, direction, the acquisition method it produces, file
patterns, a pydantic options model and a one-line description. ``aveas-format convert --from NAME``
finds it here; ``aveas-format convert --list`` prints the table.

Exporters (recording -> foreign format) register with ``direction="export"`` and have the signature
``(recording, output, *, options) -> list[Path]``.

:func:`load_converters` imports the converter modules of this package and of installed partner
packages (entry-point group ``aveas_format.converters``) through :mod:`aveas_format.plugins`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from pydantic import BaseModel, ConfigDict, ValidationError

from aveas_format import plugins
from aveas_format.errors import AveasError, FormatError, MissingCrsError


class ConverterOptions(BaseModel):
    """Base of every converter's options: unknown options are errors. A docstring under a field
    is its description (shown in docs/converters.md)."""

    model_config = ConfigDict(extra="forbid", use_attribute_docstrings=True)


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

    def parse_options(self, raw: dict[str, Any] | None) -> ConverterOptions:
        try:
            return self.options.model_validate(raw or {})
        except ValidationError as e:
            parts = [f"{'.'.join(str(p) for p in err['loc'])}: {err['msg']}" for err in e.errors()]
            raise FormatError(f"converter {self.name}: invalid options: {'; '.join(parts)}") from None

    def __call__(self, *args: Any, options: dict[str, Any] | ConverterOptions | None = None,
                 **kw: Any) -> Any:
        opts = options if isinstance(options, ConverterOptions) else self.parse_options(options)
        return self.fn(*args, options=opts, **kw)


CONVERTERS: dict[str, Converter] = {}


def converter(name: str, *, description: str, patterns: tuple[str, ...] = (),
              method: str | None = None, options: type[ConverterOptions] = ConverterOptions,
              direction: str = "import", needs_map: bool = True, version: str = "1"
              ) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register a converter function (decorator)."""
    if direction not in ("import", "export"):
        raise ValueError("direction must be 'import' or 'export'")
    key = name if direction == "import" else f"{name}:export"

    def register(fn: Callable[..., Any]) -> Callable[..., Any]:
        if key in CONVERTERS:
            raise ValueError(f"converter {name!r} ({direction}) of {fn.__module__} registered twice: "
                             f"{CONVERTERS[key].fn.__module__} has it")
        CONVERTERS[key] = Converter(name=name, direction=direction, description=description,
                                    patterns=patterns, method=method, options=options, fn=fn,
                                    needs_map=needs_map, version=version)
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
        raise FormatError(f"no {direction} converter named {name!r}; known: {', '.join(known)}")
    return reg[key]


def convert(name: str, inputs: list[str | Path], *, map_source: str | Path | bytes | None = None,
            options: dict[str, Any] | None = None, crs: str | None = None):
    """Run the importer ``name`` on ``inputs`` and return the Recording.

    ``crs`` is the recording's CRS where the map has no ``<geoReference>`` (the common import
    option ``crs``; it wins over ``options["crs"]``)."""
    conv = get_converter(name)
    if crs is not None:
        options = {**(options or {}), "crs": crs}
    paths = [Path(p) for p in inputs]
    for p in paths:
        if not p.exists():
            from aveas_format.errors import RecordingIOError

            raise RecordingIOError("input not found", path=p)
    if conv.needs_map and map_source is None:
        raise FormatError(f"converter {name} needs a map: pass --map MAP.xodr")
    try:
        return conv(paths, map_source=map_source, options=options)
    except MissingCrsError as e:
        from aveas_format.mapref.build import EXAMPLE_CRS

        cmd = (f"aveas-format convert --from {name} {' '.join(_quote(p) for p in paths)}"
               + (f" --map {_quote(map_source)}" if isinstance(map_source, (str, Path)) else "")
               + f" --crs '{EXAMPLE_CRS}' -o OUT.aveas")
        raise MissingCrsError("the map has no <geoReference>, so the recording's CRS must be given "
                              f"(API: crs=): {cmd} (a transverse Mercator at the site: put its "
                              "latitude and longitude in +lat_0/+lon_0)", path=e.path) from None
    except AveasError as e:
        if e.path is None and e.where.get("line") is not None and len(paths) == 1:
            # a located error without its file: name the (only) input
            raise type(e)(e.message, path=paths[0], **e.where) from None
        raise


def _quote(p: Any) -> str:
    import shlex

    return shlex.quote(str(p))
