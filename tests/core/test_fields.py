"""core.fields' checks of one field of a dict read from a file or a request: an accepted value
comes back as it is, and a value of the wrong type or outside the choices is a one-line
ConfigError naming the field, where it was read and what it got."""

from __future__ import annotations

import pytest

from xrayraster.core import fields
from xrayraster.core.choices import RADIOGRAPH_OUTPUTS
from xrayraster.core.errors import ConfigError

WHERE = "s.toml [scan]"


@pytest.mark.parametrize("value", [True, False])
def test_a_boolean_passes_through(value):
    assert fields.boolean(value, "noise", WHERE) is value


@pytest.mark.parametrize("value, shown", [(1, "1"), (0, "0"), ("yes", "'yes'"), ("true", "'true'"), (None, "None"),
                                          (1.0, "1.0"), ([True], "[True]")])
def test_anything_but_a_boolean_names_the_field_and_where(value, shown):
    with pytest.raises(ConfigError) as error:
        fields.boolean(value, "noise", WHERE)
    assert str(error.value) == f"s.toml [scan]: noise must be true or false, got {shown}"


@pytest.mark.parametrize("value", RADIOGRAPH_OUTPUTS)
def test_a_choice_passes_through(value):
    assert fields.choice(value, "output", WHERE, RADIOGRAPH_OUTPUTS) is value


@pytest.mark.parametrize("value, shown", [("sinogram", "'sinogram'"), ("Raw", "'Raw'"), ("", "''"), (3, "3"),
                                          (None, "None"), (True, "True"), (["raw"], "['raw']"),
                                          ({"raw": 1}, "{'raw': 1}")])
def test_anything_but_a_choice_names_the_field_where_and_the_choices(value, shown):
    with pytest.raises(ConfigError) as error:
        fields.choice(value, "output", WHERE, RADIOGRAPH_OUTPUTS)
    assert str(error.value) == f"s.toml [scan]: output must be one of raw, transmission, lineint, got {shown}"


def test_unknown_keys_are_named_with_the_allowed_ones():
    fields.only({"noise": True}, {"noise", "seed"}, "view")
    with pytest.raises(ConfigError) as error:
        fields.only({"zoom": 2, "noise": True, "tilt": 0}, {"noise", "seed"}, "view")
    assert str(error.value) == "view: unknown key(s) tilt, zoom; allowed: noise, seed"


@pytest.mark.parametrize("check, value, message", [
    (lambda v: fields.number(v, "angle_deg", "view"), True, "view: angle_deg must be a number, got True"),
    (lambda v: fields.number(v, "angle_deg", "view"), "12", "view: angle_deg must be a number, got '12'"),
    (lambda v: fields.integer(v, "seed", "view", 0), 1.5, "view: seed must be an integer >= 0, got 1.5"),
    (lambda v: fields.integer(v, "seed", "view", 0), True, "view: seed must be an integer >= 0, got True"),
    (lambda v: fields.string(v, "name", "view"), 3, "view: name must be a non-empty string, got 3"),
])
def test_a_value_of_the_wrong_json_type_is_one_line_naming_the_field(check, value, message):
    with pytest.raises(ConfigError) as error:
        check(value)
    assert str(error.value) == message and "\n" not in message
