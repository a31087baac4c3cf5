"""The roster row (CLI, seed); what a car posts and reads over the API is in `contract.vehicles`."""

from __future__ import annotations

import json
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    field_validator,
    model_validator,
)

from contract.controllers import ControllerConfigError, controller_actuations, validate_controller
from contract.values import Text64

# Which controllers can drive which actuation, from the vehicle agent's controller registry (the
# single source of truth: a controller added there is accepted here).
CONTROLLER_ACTUATIONS: dict[str, frozenset[str]] = controller_actuations()


class RosterRow(BaseModel):
    """One vehicle of the fleet roster."""

    model_config = ConfigDict(extra="forbid", str_strip_whitespace=True)

    vehicle_id: str = Field(pattern=r"^[A-Za-z0-9_-]{1,32}$")
    vin: str = Field(pattern=r"^[A-HJ-NPR-Z0-9]{17}$")
    # Text as the API stores it (no NUL, at most 64 characters, as an assignment's route): a
    # NUL reached the database as a raw error naming no row, and a 5,000-character route
    # was imported that the car's next assignment change then refused.
    make: Text64 = Field(min_length=1)
    model: Text64 = Field(min_length=1)
    year: int = Field(ge=1990, le=2100)
    actuation: Literal["acc", "accel"]
    corridor_id: Text64 = Field(min_length=1)
    route: Text64 = Field(min_length=1)
    assigned_lane: int = Field(ge=1)
    controller_name: str
    controller_params: dict[str, Any] = Field(default_factory=dict)

    @field_validator("controller_params", mode="before")
    @classmethod
    def _params_from_json(cls, value: object) -> object:
        if value is None or value == "":
            return {}
        if isinstance(value, str):
            try:
                return json.loads(value)
            except json.JSONDecodeError as error:
                raise ValueError(f"not valid JSON ({error.msg})") from None
            except RecursionError:  # "[" * 100000: deeper than the parser goes
                raise ValueError("nested too deeply") from None
        return value

    @model_validator(mode="after")
    def _controller_fits_actuation(self) -> RosterRow:
        actuations = CONTROLLER_ACTUATIONS.get(self.controller_name)
        if actuations is None:
            known = ", ".join(sorted(CONTROLLER_ACTUATIONS))
            raise ValueError(f"controller_name {self.controller_name!r} is not one of {known}")
        if self.actuation not in actuations:
            raise ValueError(
                f"controller {self.controller_name!r} cannot drive actuation {self.actuation!r}"
            )
        try:
            # the schema the car builds its controller from, as for an assignment
            validate_controller(self.controller_name, self.actuation, self.controller_params)
        except ControllerConfigError as error:
            field = "controller_" + error.field.removeprefix("controller.")
            raise ValueError(f"{field}: {error.reason}") from None
        return self
