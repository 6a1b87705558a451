"""Converters from and to foreign formats, one module per format, found through the registry.

>>> from aveas_format.converters import convert
>>> rec = convert("sumo-fcd", ["fcd.xml"], map_source="net.xodr", options={"net_file": "net.net.xml"})
>>> rec, states, on_map = convert_to("openlabel", ["big.json"], "big.aveas")  # written (bounded memory)
"""

from aveas_format.converters.registry import (
    CONVERTERS,
    Converter,
    ConverterOptions,
    ImportOptions,
    convert,
    convert_to,
    converter,
    get_converter,
    load_converters,
)

__all__ = ["CONVERTERS", "Converter", "ConverterOptions", "ImportOptions", "convert", "convert_to", "converter", "get_converter",
           "load_converters"]
