"""A second ``sumo-fcd`` importer."""

from __future__ import annotations

from aveas_format.converters.registry import converter


@converter("sumo-fcd", description="not the real one")
def convert(inputs, *, map_source, options):
    raise NotImplementedError
