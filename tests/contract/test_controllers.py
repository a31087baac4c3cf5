"""The controller schemas: what a config may name, and the field a refusal points at."""

from __future__ import annotations

import pickle
from typing import Any

import jsonschema_rs
import pytest

from contract.controllers import (
    CONTROLLER_SCHEMAS,
    ControllerConfigError,
    MicroAccelParams,
    WrongActuation,
    controller_choice_schema,
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
        # a_safe's gap assumes braking the agent may not command (it requests at most -3)
        (
            "microaccel",
            "accel",
            {"min_accel_mps2": -8.0},
            "controller.params.min_accel_mps2",
            "greater than or equal to -3",
        ),
        (
            "simple",
            "accel",
            {"safety_min_accel_mps2": -5.0},
            "controller.params.safety_min_accel_mps2",
            "greater than or equal to -3",
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


def test_a_controller_for_the_other_actuation_is_its_own_error() -> None:
    """The API answers it 409 (the body is valid, the vehicle cannot take it), so it is typed."""
    with pytest.raises(WrongActuation):
        validate_controller("microaccel", "acc", {})
    with pytest.raises(ControllerConfigError) as refused:
        validate_controller("pid", "acc", {})
    assert not isinstance(refused.value, WrongActuation)


@pytest.mark.parametrize(
    ("controller", "valid"),
    [
        ({"name": "simple"}, True),
        ({"name": "simple", "params": {"k": 0.4, "gap_setting": 2}}, True),
        ({"name": "simple", "params": {"gap_setting": 2.0}}, True),  # JSON Schema's integer
        ({"name": "microaccel_acc", "params": {"base": {"lane_change": {"c": 0.5}}}}, True),
        ({"name": "rl_acc", "params": {"policy": "policies/a.npz"}}, True),
        ({"name": "pid"}, False),
        ({"name": "simple", "params": {"k": "0.5"}}, False),  # text is not a number
        ({"name": "simple", "params": {"k": True}}, False),
        ({"name": "simple", "params": {"k": 0}}, False),  # k > 0
        ({"name": "simple", "params": {"gap_setting": 2.5}}, False),
        ({"name": "simple", "params": {"gap_setting": "2"}}, False),
        ({"name": "simple", "params": {"bogus": 1}}, False),
        ({"name": "microaccel", "params": {"lane_change": {"enabled": 1}}}, False),
        ({"name": "microaccel", "params": {"lane_change": {"c": 1.5}}}, False),
        ({"name": "microaccel_acc", "params": {"base": {"bogus": 1}}}, False),
        ({"name": "rl_acc", "params": {"policy": ""}}, False),
        ({"name": "rl_acc", "params": {"policy": "a\u0000b"}}, False),
    ],
)
def test_the_documented_schema_accepts_exactly_what_validation_accepts(
    controller: dict[str, Any], valid: bool
) -> None:
    documented = jsonschema_rs.validator_for(controller_choice_schema()).is_valid(controller)
    try:
        validate_controller(controller["name"], None, controller.get("params"))
        accepted = True
    except ControllerConfigError:
        accepted = False
    assert (documented, accepted) == (valid, valid)


def test_every_registered_controller_is_one_alternative_of_the_schema() -> None:
    alternatives = controller_choice_schema()["oneOf"]
    assert [a["properties"]["name"]["const"] for a in alternatives] == list(CONTROLLER_SCHEMAS)


def test_nested_params_are_validated_whole() -> None:
    params = validate_controller("microaccel", "accel", {"k": 0.4, "lane_change": {"c": 0.5}})
    assert isinstance(params, MicroAccelParams)
    assert params.k == 0.4
    assert params.lane_change.c == 0.5


@pytest.mark.parametrize("error_class", [ControllerConfigError, WrongActuation])
def test_a_config_error_crosses_a_process_boundary_as_itself(
    error_class: type[ControllerConfigError],
) -> None:
    """A simulation worker's refusal is pickled to the process that started it."""
    error = error_class("controller.params.k", "too small", "controller microaccel: params.k")
    copy = pickle.loads(pickle.dumps(error))
    assert type(copy) is error_class
    assert (copy.field, copy.reason, str(copy)) == (
        "controller.params.k",
        "too small",
        "controller microaccel: params.k",
    )
