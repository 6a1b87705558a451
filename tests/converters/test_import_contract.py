"""What every importer shares, walked over the registry: the options read by their declared type
(``-O KEY=VALUE``)."""

from __future__ import annotations

import typing

import pytest

from aveas_format.cli.options import coerce_option, parse_option_pairs
from aveas_format.converters.registry import get_converter, load_converters


def test_option_values_are_read_by_their_declared_type():
    """``-O subject_id=1`` of a text option is the text "1" (it failed "Input should be a valid
    string"); numbers, booleans, literals, tuples and dict entries by their type."""
    sim = get_converter("driving-simulator")
    raw = parse_option_pairs(["subject_id=1", "partner=7"], sim.options)
    assert raw == {"subject_id": "1", "partner": "7"}
    assert sim.parse_options(raw).subject_id == "1"
    osc = get_converter("openscenario")
    raw = parse_option_pairs(["parameter.Speed=60", "parameter.Name=ego", "parameter.On=true",
                              "rate_hz=10"], osc.options)
    assert raw == {"parameter": {"Speed": 60, "Name": "ego", "On": True}, "rate_hz": 10.0}
    rot = get_converter("rotated-boxes")
    raw = parse_option_pairs(["angle_unit=RAD", "image_size=640,480", "geotransform=none"], rot.options)
    assert raw == {"angle_unit": "rad", "image_size": [640, 480], "geotransform": None}
    assert rot.parse_options(raw).image_size == (640, 480)
    # an options file or the API: a number for a text option is its text
    assert sim.parse_options({"subject_id": 12}).subject_id == "12"


@pytest.mark.parametrize("pair,needle", [
    ("frame_offset=1,2", "option frame_offset: expected 3 comma-separated values, got 2"),
    ("z_reference=centre", "expected one of 'center', 'bottom', got 'centre' (did you mean 'center'?)"),
    ("keep_non_road_users=maybe", "expected a boolean (true/false), got 'maybe'"),
    ("rate_hz=fast", None),
])
def test_a_value_of_the_wrong_type_names_the_option_and_the_type(pair, needle):
    model = get_converter("infra-lidar" if not pair.startswith("rate_hz") else "openscenario").options
    with pytest.raises(ValueError) as e:
        parse_option_pairs([pair], model)
    assert str(e.value) == "option rate_hz: expected a number, got 'fast'" if needle is None \
        else needle in str(e.value)


def _leaves(ann):
    origin = typing.get_origin(ann)
    if origin is None:
        return [ann]
    return [x for a in typing.get_args(ann) if a is not Ellipsis for x in _leaves(a)]


def test_every_option_type_of_every_converter_is_read():
    """No option of any registered converter (importers and exporters) has a type the reader
    does not know: each field's default, written as text, reads back as the same value."""
    for conv in load_converters().values():
        for name, f in conv.options.model_fields.items():
            d = f.get_default(call_default_factory=True)
            if d is None or isinstance(d, (dict, list)) and not d or f.exclude:
                continue
            if isinstance(d, (list, tuple)):
                text = ",".join(str(v) for v in d)
            elif isinstance(d, bool):
                text = str(d).lower()
            else:
                text = str(getattr(d, "value", d))
            got = coerce_option(name, text, f.annotation)
            ok = conv.options.model_validate({name: got})
            assert getattr(ok, name) == d or str(getattr(ok, name)) == str(d), (conv.name, name)
