"""Vehicles' shapes: the roster row (CLI, seed) and what a car posts and reads over the API."""

from __future__ import annotations

import json
from typing import Any, Literal

from pydantic import (
    AwareDatetime,
    BaseModel,
    ConfigDict,
    Field,
    field_validator,
    model_validator,
)

from vehicle_agent.controllers import controller_actuations

# Which controllers can drive which actuation, from the vehicle agent's controller registry (the
# single source of truth: a controller added there is accepted here).
CONTROLLER_ACTUATIONS: dict[str, frozenset[str]] = controller_actuations()


class RosterRow(BaseModel):
    """One vehicle of the fleet roster."""

    model_config = ConfigDict(extra="forbid", str_strip_whitespace=True)

    vehicle_id: str = Field(pattern=r"^[A-Za-z0-9_-]{1,32}$")
    vin: str = Field(pattern=r"^[A-HJ-NPR-Z0-9]{17}$")
    make: str = Field(min_length=1)
    model: str = Field(min_length=1)
    year: int = Field(ge=1990, le=2100)
    actuation: Literal["acc", "accel"]
    corridor_id: str = Field(min_length=1)
    route: str = Field(min_length=1)
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
        return self


# --- what a vehicle posts and reads (../shared/interfaces.md, "Vehicles") --------------------

VEHICLE_ID_PATTERN = r"^[A-Za-z0-9_-]{1,32}$"
# A batch is the agent's store-and-forward upload: at most this many pings per request.
MAX_PINGS_PER_BATCH = 1000


class Ping(BaseModel):
    """One 1 Hz ping of a vehicle; `ts` is the car's GPS-disciplined clock.

    Unknown fields are ignored, so a newer agent may send fields this server does not know yet.
    Lane and the time window are checked against the corridor and the clock at ingest.
    """

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    vehicle_id: str = Field(pattern=VEHICLE_ID_PATTERN)
    ts: AwareDatetime
    lat: float = Field(ge=-90, le=90)
    lon: float = Field(ge=-180, le=180)
    speed_mps: float = Field(ge=0, le=90)
    accel_mps2: float | None = Field(None, ge=-50, le=50)
    heading_deg: float | None = Field(None, ge=0, le=360)
    lane: int | None = Field(None, ge=1, le=12)
    acc_engaged: bool | None = None
    controller_engaged: bool | None = None
    controller: str | None = Field(None, max_length=64)
    acc_speed_setting_mph: float | None = Field(None, ge=0, le=200)
    acc_gap_setting: int | None = Field(None, ge=1, le=3)
    lead_present: bool | None = Field(None, description="the car's 'minicar' lead flag")
    lead_distance_m: float | None = Field(None, ge=0, le=1000)
    lead_rel_speed_mps: float | None = Field(None, ge=-90, le=90)
    plan_id: int | None = Field(None, ge=0, le=2**63 - 1)


class PingBatch(BaseModel):
    """The store-and-forward upload: up to 1000 pings in one request."""

    pings: list[Ping] = Field(max_length=MAX_PINGS_PER_BATCH)


class Rejection(BaseModel):
    """A ping refused on its own (the others of its batch are kept)."""

    index: int
    error: str


class PingAnswer(BaseModel):
    """Sent only after the accepted rows are committed."""

    accepted: int
    duplicates: int
    rejected: list[Rejection]


class VehicleStatusReport(BaseModel):
    """The piStatus report a car posts every ~10 s (all but `ts` optional)."""

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    ts: AwareDatetime
    agent_version: str | None = Field(None, max_length=64)
    uptime_s: float | None = Field(None, ge=0)
    can_ok: bool | None = None
    can_msgs_per_s: float | None = Field(None, ge=0)
    gps_fix: bool | None = None
    gps_satellites: int | None = Field(None, ge=0, le=255)
    acc_available: bool | None = None
    controller: str | None = Field(None, max_length=64)
    controller_running: bool | None = None
    plan_id: int | None = Field(None, ge=0, le=2**63 - 1)
    plan_age_s: float | None = Field(None, ge=0)
    spool_backlog: int | None = Field(None, ge=0, le=2**31 - 1)
    disk_free_mb: float | None = Field(None, ge=0)
    cpu_temp_c: float | None = Field(None, ge=-60, le=150)
    ups_on_battery: bool | None = None
    server_rtt_ms: float | None = Field(None, ge=0)


class StatusAnswer(BaseModel):
    """1 stored, or 0 and 1 duplicate when the same report (vehicle, ts) was already stored."""

    accepted: int
    duplicates: int


class ControllerConfig(BaseModel):
    """Which controller the agent runs, and its parameters."""

    name: str
    params: dict[str, Any]


class VehicleConfig(BaseModel):
    """What a vehicle should run: its identity, assignment, controller and agent periods."""

    vehicle_id: str
    make: str
    model: str
    year: int
    actuation: Literal["acc", "accel"]
    corridor_id: str
    route: str
    assigned_lane: int
    controller: ControllerConfig
    active: bool = Field(description="false: the agent leaves the car to its stock ACC")
    in_maintenance: bool
    ping_period_s: float
    status_period_s: float
    plan_poll_s: float
    stale_plan_after_s: float
