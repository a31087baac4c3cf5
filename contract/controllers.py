"""The controllers a vehicle config may name, and the schema of each one's parameters.

The server checks an assignment against these before it saves it, and the agent builds its
controller from the same models, so a car never receives a config it cannot run. The agent's
registry (`vehicle_agent.controllers.registry`) pairs each name with its implementation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from contract.units import MPS_PER_MPH
from contract.values import StorableText, json_number

Actuation = Literal["acc", "accel"]
ACTUATIONS: tuple[Actuation, ...] = ("acc", "accel")

# ACC gap settings: 1..3 bars (paper: roughly 1.2, 1.5 and 2.0 s time gaps).
MIN_GAP_SETTING = 1
MAX_GAP_SETTING = 3
# The hardest braking the agent may request of an `accel` car (m/s^2; the issue's [-3, 1.5]
# window, vehicle_agent.actuators.AccelLimits). a_safe's gap assumes the ego can brake this
# hard, so no controller parameter may plan with harder braking than it can command.
AGENT_MIN_ACCEL_MPS2 = -3.0
# The largest acceleration the agent commands (m/s^2, the window's top): a controller may plan
# with more (MicroAccel's a_max), and the agent's limiter caps what it sends.
AGENT_MAX_ACCEL_MPS2 = 1.5
# The fleet's top speed (mph): the paper's "modest speeds in excess of the posted speed limit
# of 70 mph", the top of its clip on every ACC speed setting. An `acc` car's stock ACC holds the
# clipped setting; an `accel` car has no setting holding it, so the agent's acceleration limiter
# keeps it under this speed (vehicle_agent.actuators.AccelLimits).
FLEET_TOP_SPEED_MPH = 73.0
FLEET_TOP_SPEED_MPS = FLEET_TOP_SPEED_MPH * MPS_PER_MPH

# Parameters arrive as JSON: a number is a JSON number and a flag a JSON boolean, as the schema
# (`controller_choice_schema`) says; lax coercion would take "0.5" or 1 and so accept what the
# schema calls invalid. Non-finite numbers (NaN, 1e999) are refused: JSONB cannot store them.
_PARAMS_CONFIG = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)
# A bar count as JSON Schema's "integer" reads it (2 or 2.0), never text or a boolean.
# (Field before the validator: the other order leaves `ge`/`le` unnamed in the JSON Schema.)
GapSetting = Annotated[
    int,
    Field(strict=False, ge=MIN_GAP_SETTING, le=MAX_GAP_SETTING),
    BeforeValidator(json_number),
]


class LaneChangeParams(BaseModel):
    """Lane-change recovery parameters (paper values where the paper gives them)."""

    model_config = _PARAMS_CONFIG

    enabled: bool = True
    # h_safe: acceptable time gap (s); C_safe: acceptable time to collision (s).
    safe_time_gap_s: float = Field(2.0, gt=0)
    safe_ttc_s: float = Field(4.5, gt=0)
    # t*: f1's slope; dv*: f2's offset (paper: "Delta v*"); c: weight of f1 in alpha.
    t_star: float = Field(1.32, gt=0)
    dv_star: float = Field(10.3, gt=0)
    c: float = Field(0.75, ge=0, le=1)
    # epsilon (m/s^2): the smoothing stops once |a_k - u_k| is this small.
    epsilon_mps2: float = Field(0.05, gt=0)
    # A gap change this much beyond what the relative speed explains is a lane change (m); radar
    # noise is well under a metre, a cut-in changes the gap by tens of metres.
    gap_jump_m: float = Field(4.0, gt=0)
    # A step asking more jerk than this is significant (m/s^3): 0.5 m/s^2 in one 0.1 s period.
    jerk_threshold_mps3: float = Field(5.0, gt=0)
    max_smoothing: float = Field(0.95, ge=0, lt=1)


class MicroAccelParams(BaseModel):
    """MicroAccel gains and limits (paper eq. a_safe, a_target, a_MPC)."""

    model_config = _PARAMS_CONFIG

    # k: gain of the safety and target terms (1/s).
    k: float = Field(0.5, gt=0, le=5)
    # s0: standstill safety distance (m).
    standstill_gap_m: float = Field(5.0, ge=0, le=50)
    # a_min: the ego's hardest planned braking (m/s^2, negative), also the command floor; no
    # harder than the agent may command.
    min_accel_mps2: float = Field(AGENT_MIN_ACCEL_MPS2, lt=0, ge=AGENT_MIN_ACCEL_MPS2)
    # a_l,min: the leader's hardest possible braking (m/s^2, negative); harder than ours keeps
    # the equilibrium gap near 1.9 s at 25 m/s with the defaults.
    lead_min_accel_mps2: float = Field(-5.0, lt=0, ge=-10)
    # a_max: the ego's largest acceleration (m/s^2), also the command ceiling; above
    # AGENT_MAX_ACCEL_MPS2 the agent's limiter caps what is sent.
    max_accel_mps2: float = Field(AGENT_MAX_ACCEL_MPS2, gt=0, le=4)
    # k2: gain of the anticipation term when the leader accelerates (1/(m/s)).
    k2: float = Field(0.2, ge=0, le=5)
    # Time constant (s) of the low-pass on the leader's finite-difference acceleration.
    lead_accel_filter_s: float = Field(0.5, ge=0, le=10)
    lane_change: LaneChangeParams = LaneChangeParams()


class SimpleParams(BaseModel):
    """Simple controller parameters."""

    model_config = _PARAMS_CONFIG

    # Gain of the target term (1/s) and the bounds of the command (m/s^2), accel cars.
    k: float = Field(0.5, gt=0, le=5)
    max_accel_mps2: float = Field(1.0, gt=0, le=AGENT_MAX_ACCEL_MPS2)
    min_accel_mps2: float = Field(-2.0, lt=0, ge=AGENT_MIN_ACCEL_MPS2)
    # Safety term parameters (see MicroAccelParams).
    standstill_gap_m: float = Field(5.0, ge=0, le=50)
    lead_min_accel_mps2: float = Field(-5.0, lt=0, ge=-10)
    safety_min_accel_mps2: float = Field(AGENT_MIN_ACCEL_MPS2, lt=0, ge=AGENT_MIN_ACCEL_MPS2)
    # Added to the target on acc cars (mph), e.g. to offset a speedometer bias.
    speed_offset_mph: float = Field(0.0, ge=-10, le=10)
    gap_setting: GapSetting = MAX_GAP_SETTING


class MicroAccelAccParams(BaseModel):
    """MicroAccel-to-set-points parameters."""

    model_config = _PARAMS_CONFIG

    base: MicroAccelParams = MicroAccelParams()
    # How far ahead the plan is read (s at the current speed), and at least this far (m).
    lookahead_s: float = Field(20.0, gt=0, le=120)
    min_lookahead_m: float = Field(200.0, gt=0, le=5000)
    # tau: how fast the stock ACC follows a speed setting (s).
    acc_response_s: float = Field(2.0, gt=0, le=20)
    # A target this much below the current speed ahead is a slowdown (m/s), or a needed
    # deceleration this strong (m/s^2).
    slowdown_mps: float = Field(2.0, gt=0)
    slowdown_accel_mps2: float = Field(-0.3, lt=0)
    congested_gap_setting: GapSetting = MAX_GAP_SETTING
    free_gap_setting: GapSetting = 2
    gap_dwell_s: float = Field(10.0, ge=0)


# A policy is named by the lowercase hex sha256 of its file (docs/interfaces.md, "Policies").
POLICY_SHA256_PATTERN = r"^[0-9a-f]{64}$"
RL_CONTROLLERS: dict[str, Actuation] = {"rl_acc": "acc", "rl_accel": "accel"}


class RlParams(BaseModel):
    """An RL controller's policy.

    `policy_sha256` names a policy the server stores (`POST /api/v1/policies`): the agent
    downloads it once, checks the digest and keeps it in its state dir. `policy` is a `.npz`
    already on the car (checked against `policy_sha256` when both are given). Neither: the
    policy the agent ships (`vehicle_agent/controllers/policies/rl_<actuation>.npz`).
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    policy: StorableText | None = Field(None, min_length=1)
    policy_sha256: str | None = Field(None, pattern=POLICY_SHA256_PATTERN)


class ControllerConfigError(ValueError):
    """A controller a car cannot run: `field` names what is wrong (`controller.name`,
    `controller.params.<path>`), `reason` says why, and the message says both."""

    def __init__(self, field: str, reason: str, message: str) -> None:
        super().__init__(message)
        self.field = field
        self.reason = reason

    def __reduce__(self) -> tuple[type[ControllerConfigError], tuple[str, str, str]]:
        """Rebuilt from all three parts: a simulation worker's error reaches the process that
        started it as itself (pickle's default would call the class with the message alone,
        and the failed rebuild breaks the whole process pool)."""
        return (type(self), (self.field, self.reason, str(self)))


class WrongActuation(ControllerConfigError):
    """A registered controller with valid parameters that cannot drive this vehicle's actuation:
    the assignment is sound, but not for this car (the API answers 409, not 422)."""


@dataclass(frozen=True)
class ControllerSchema:
    """One controller a config may name: the actuations it drives and its parameters' model."""

    actuations: frozenset[Actuation]
    params_model: type[BaseModel]
    summary: str


CONTROLLER_SCHEMAS: dict[str, ControllerSchema] = {
    "simple": ControllerSchema(
        frozenset({"acc", "accel"}),
        SimpleParams,
        "follows the plan's target speed at the vehicle's position, bounded",
    ),
    "microaccel": ControllerSchema(
        frozenset({"accel"}),
        MicroAccelParams,
        "min(a_safe, a_target, a_MPC) with lane-change recovery (acceleration requests)",
    ),
    "microaccel_acc": ControllerSchema(
        frozenset({"acc"}),
        MicroAccelAccParams,
        "MicroAccel anticipation as ACC speed setting and gap bars",
    ),
    "rl_acc": ControllerSchema(
        frozenset({"acc"}),
        RlParams,
        "PPO-trained policy: ACC speed setting and gap bars (paper, ACC-Based Controller)",
    ),
    "rl_accel": ControllerSchema(
        frozenset({"accel"}),
        RlParams,
        "PPO-trained policy: acceleration request bounded by MicroAccel's a_safe",
    ),
}


def controller_actuations() -> dict[str, frozenset[str]]:
    """Controller name -> the actuations it can drive."""
    return {name: frozenset(schema.actuations) for name, schema in CONTROLLER_SCHEMAS.items()}


def validate_controller(
    name: str, actuation: str | None, params: Mapping[str, Any] | None
) -> BaseModel:
    """The controller's params model, or ControllerConfigError naming the field at fault.

    The message first (name, then parameters), the vehicle last: WrongActuation only for a
    controller that is valid in itself. `actuation` None checks the message only.
    """
    schema = CONTROLLER_SCHEMAS.get(name)
    if schema is None:
        known = ", ".join(sorted(CONTROLLER_SCHEMAS))
        reason = f"{name!r} is not one of {known}"
        raise ControllerConfigError("controller.name", reason, f"controller {reason}")
    try:
        model = schema.params_model.model_validate(dict(params or {}))
    except ValidationError as error:
        detail = error.errors()[0]
        where = ".".join(str(part) for part in detail.get("loc", ()))
        field = f"params.{where}" if where else "params"
        reason = str(detail.get("msg", "invalid"))
        raise ControllerConfigError(
            f"controller.{field}", reason, f"controller {name}: {field}: {reason}"
        ) from None
    if actuation is not None and actuation not in schema.actuations:
        reason = f"{name!r} cannot drive actuation {actuation!r}"
        raise WrongActuation("controller.name", reason, f"controller {reason}")
    return model


def controller_choice_schema() -> dict[str, Any]:
    """The JSON Schema of a config's `controller` object, `{"name": ..., "params": {...}}`:
    exactly what `validate_controller` accepts apart from the actuation (a property of the
    vehicle, not of the message). One alternative per registry entry, the name a `const` and
    the params its own model's schema (ranges stated, unknown fields refused), so the OpenAPI
    document follows the registry: a new controller is still one model and one entry.
    """
    alternatives: list[dict[str, Any]] = []
    for name, schema in CONTROLLER_SCHEMAS.items():
        params = schema.params_model.model_json_schema()
        drives = " and ".join(f"`{kind}`" for kind in ACTUATIONS if kind in schema.actuations)
        alternatives.append(
            {
                "type": "object",
                "title": name,
                "description": f"{schema.summary}; drives {drives} cars",
                "properties": {
                    "name": {"const": name},
                    "params": _inlined(params, params.get("$defs", {})),
                },
                "required": ["name"],
                "additionalProperties": False,
            }
        )
    return {"oneOf": alternatives}


def _inlined(schema: Any, definitions: Mapping[str, Any]) -> Any:
    """`schema` with each `{"$ref": "#/$defs/X"}` replaced by X itself (the params models nest
    but never recurse), so the alternative stands alone wherever a document puts it."""
    if isinstance(schema, list):
        return [_inlined(item, definitions) for item in schema]
    if not isinstance(schema, dict):
        return schema
    reference = schema.get("$ref")
    if isinstance(reference, str) and reference.startswith("#/$defs/"):
        target = dict(definitions[reference.removeprefix("#/$defs/")])
        rest = {key: value for key, value in schema.items() if key != "$ref"}
        return _inlined({**target, **rest}, definitions)
    return {key: _inlined(value, definitions) for key, value in schema.items() if key != "$defs"}
