"""The controller schemas: what a config may name, and the field a refusal points at."""

from __future__ import annotations

import pytest

from contract.controllers import (
    CONTROLLER_SCHEMAS,
    ControllerConfigError,
    MicroAccelParams,
    validate_controller,
)


def test_defaults_are_a_runnable_config() -> None:
    for name, schema in CONTROLLER_SCHEMAS.items():
        for actuation in schema.actuations:
            assert isinstance(validate_controller(name, actuation, {}), schema.params_model)


@pytest.mark.parametrize(
    ("name", "actuation", "params", "field", "reason"),
    [
        ("pid", "accel", {}, "controller.name", "'pid' is not one of microaccel, "),
        ("microaccel", "acc", {}, "controller.name", "cannot drive actuation 'acc'"),
        ("simple", "acc", {"bogus": 1}, "controller.params.bogus", "Extra inputs"),
        ("simple", "acc", {"k": -0.5}, "controller.params.k", "greater than 0"),
        ("simple", "accel", {"k": "fast"}, "controller.params.k", "valid number"),
        (
            "microaccel",
            "accel",
            {"lane_change": {"c": 2}},
            "controller.params.lane_change.c",
            "less than or equal to 1",
        ),
    ],
)
def test_a_refusal_names_the_field_and_the_reason(
    name: str, actuation: str, params: dict[str, object], field: str, reason: str
) -> None:
    with pytest.raises(ControllerConfigError) as refused:
        validate_controller(name, actuation, params)
    assert refused.value.field == field
    assert reason in refused.value.reason


def test_nested_params_are_validated_whole() -> None:
    params = validate_controller("microaccel", "accel", {"k": 0.4, "lane_change": {"c": 0.5}})
    assert isinstance(params, MicroAccelParams)
    assert params.k == 0.4
    assert params.lane_change.c == 0.5
