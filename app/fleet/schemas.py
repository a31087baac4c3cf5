"""Operations API bodies: the fleet with readiness, and assignment and maintenance changes.

Field names follow the vehicle-facing API (`acc_engaged`, `gps_fix`, ...) rather than the
warehouse columns (`is_acc_engaged`, `has_gps_fix`), so a status reads the same in and out.
"""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    StrictBool,
    StringConstraints,
    WithJsonSchema,
    field_validator,
)

from app.fleet.service import MAX_NOTE_LENGTH, MAX_ROUTE_LENGTH, FleetCounts, FleetEntry
from contract.controllers import controller_choice_schema
from contract.values import NO_NUL_PATTERN, StorableText, json_number, storable_text


class ControllerAssignment(BaseModel):
    """A controller by name with its parameters."""

    model_config = ConfigDict(extra="forbid")

    name: StorableText = Field(min_length=1, max_length=64, examples=["microaccel_acc"])
    params: dict[str, Any] = Field(default_factory=dict)


# White space as `str.strip()` removes it, spelled out: `\s` means different sets in Python,
# in JavaScript and in the Rust engine pydantic uses, so a pattern with it would not say the same
# thing to every reader of the document.
WHITE_SPACE = (
    "\\u0009-\\u000d\\u001c-\\u0020\\u0085\\u00a0\\u1680\\u2000-\\u200a"
    "\\u2028\\u2029\\u202f\\u205f\\u3000"
)
# A route names something: no NUL, and at least one character that is not white space (the
# service strips it). The pattern is the document's; the check is `_names_something`, whose
# error says so in words where the pattern's quoted three hundred characters of it.
ROUTE_PATTERN = f"^[{WHITE_SPACE}]*[^{WHITE_SPACE}\\u0000][^\\u0000]*$"


def _names_something(route: str) -> str:
    if not route.strip():
        raise ValueError("a route needs a character that is not white space")
    return route


# A maintenance note: the bound on the string itself, so its error counts characters.
NoteText = Annotated[
    str,
    StringConstraints(max_length=MAX_NOTE_LENGTH),
    AfterValidator(storable_text),
    Field(json_schema_extra={"pattern": NO_NUL_PATTERN}),
]


class AssignmentIn(BaseModel):
    """What a vehicle should drive: lane, route and controller (all three, PUT semantics).

    The document states the controller as one alternative per registered controller with its
    own parameters (`contract.controllers.controller_choice_schema`); the service checks the
    same registry. What depends on the vehicle, not the message (its corridor's lanes, the
    actuation the controller must drive), is answered 409.
    """

    model_config = ConfigDict(extra="forbid")

    lane: int = Field(
        ge=1,
        le=12,
        description="Lane numbered from 1 at the left (median side); at most the number of "
        "lanes of the vehicle's corridor (409 otherwise).",
    )
    route: Annotated[str, AfterValidator(storable_text), AfterValidator(_names_something)] = Field(
        min_length=1,
        max_length=MAX_ROUTE_LENGTH,
        json_schema_extra={"pattern": ROUTE_PATTERN},
    )
    controller: Annotated[
        ControllerAssignment, WithJsonSchema(controller_choice_schema(), mode="validation")
    ]
    config_version: int | None = Field(
        default=None,
        ge=1,
        description="The vehicle's `config_version` this change was made against (as `GET "
        "/api/v1/fleet` lists it). When given, a vehicle changed since is refused with 409 on "
        "this field and nothing is saved, so two operators never silently overwrite each other. "
        "Left out, the change applies to whatever the vehicle holds.",
    )

    # true is not lane 1, nor "2" lane 2: integers take JSON numbers only, as everywhere
    _integers = field_validator("lane", "config_version", mode="before")(json_number)


class AssignmentOut(AssignmentIn):
    """The vehicle's assignment after the change."""

    model_config = ConfigDict(extra="forbid")

    controller: ControllerAssignment
    config_version: int = Field(description="the vehicle's config version after this change")
    vehicle_id: str
    corridor_id: str
    updated_at: datetime


class MaintenanceIn(BaseModel):
    """Take a vehicle out of service (or put it back), with a note saying why."""

    model_config = ConfigDict(extra="forbid")

    # strict: the document says boolean, so 0 or "yes" is refused, not read as a guess
    in_maintenance: StrictBool
    note: NoteText | None = None
    config_version: int | None = Field(
        default=None,
        ge=1,
        description="The vehicle's `config_version` this change was made against, as for an "
        "assignment: a vehicle changed since is refused with 409 on this field and nothing is "
        "saved. Left out, the change applies to whatever the vehicle holds.",
    )

    _integers = field_validator("config_version", mode="before")(json_number)


class MaintenanceOut(MaintenanceIn):
    """The vehicle's maintenance state after the change."""

    config_version: int = Field(description="the vehicle's config version after this change")
    vehicle_id: str


MESSAGE_AGE = (
    "seconds since the car sent it, as the readiness checks grade it: from its ts, or from when "
    "the server received it if that was earlier (a car clock ahead shows no negative age), less "
    "how far behind the server stores what the fleet sends (READINESS_SERVER_LAG_S at most), "
    "but never less than the time since the server stored it"
)


class PingOut(BaseModel):
    """A vehicle's newest ping."""

    ts: datetime
    received_at: datetime
    age_s: float = Field(description=MESSAGE_AGE)
    speed_mps: float
    x_m: float | None
    postmile: float | None
    corridor_id: str | None = Field(
        None,
        description="the corridor x_m and postmile lie along: the one the car was assigned at "
        "the ping's ts (which the vehicle's current corridor_id need not be)",
    )
    lane: int | None
    acc_engaged: bool | None
    controller_engaged: bool | None
    controller: str | None
    plan_id: int | None
    policy_sha256: str | None = Field(None, description="the policy the controller runs")


class StatusOut(BaseModel):
    """A vehicle's newest piStatus report."""

    ts: datetime
    received_at: datetime
    age_s: float = Field(description=MESSAGE_AGE)
    agent_version: str | None
    uptime_s: float | None
    can_ok: bool | None
    can_msgs_per_s: float | None
    gps_fix: bool | None
    gps_satellites: int | None
    acc_available: bool | None
    controller: str | None
    controller_running: bool | None
    plan_id: int | None
    plan_age_s: float | None
    spool_backlog: int | None
    spool_dropped: int | None = Field(
        None, description="pings the car's spool dropped unsent (full), since the spool was made"
    )
    disk_free_mb: float | None
    cpu_temp_c: float | None
    ups_on_battery: bool | None
    server_rtt_ms: float | None
    policy_sha256: str | None = Field(None, description="the policy the controller runs")
    engage_reason: str | None = Field(
        None, description="why the agent commands the car or leaves it to its stock ACC"
    )


class CheckOut(BaseModel):
    """One readiness check."""

    name: str
    label: str
    level: Literal["green", "amber", "red", "unknown"]
    value: str
    detail: str
    reason: str = Field(description="why the check is not green, in words; empty when green")
    pending: str = Field(description="a level change waiting out the hysteresis hold, if any")


class FleetVehicleOut(BaseModel):
    """A vehicle, its assignment, last ping, last status, checks and verdict."""

    vehicle_id: str
    make: str
    model: str
    year: int
    actuation: str
    corridor_id: str
    route: str
    assigned_lane: int
    controller: ControllerAssignment
    config_version: int = Field(
        description="bumped by every change of the assignment or maintenance; send it with a "
        "change of assignment to refuse one made since"
    )
    active: bool
    in_maintenance: bool
    maintenance_note: str | None
    last_ping: PingOut | None
    last_status: StatusOut | None
    checks: list[CheckOut]
    verdict: Literal["cleared", "not cleared", "maintenance", "inactive"]
    cleared: bool
    problems: list[str]


class FleetCountsOut(BaseModel):
    """Counts over the vehicles listed."""

    vehicles: int
    cleared: int
    not_cleared: int
    maintenance: int
    inactive: int
    reporting: int
    engaged: int


class FleetOut(BaseModel):
    """The fleet at `generated_at`."""

    generated_at: datetime
    counts: FleetCountsOut
    vehicles: list[FleetVehicleOut]


def fleet_vehicle_out(entry: FleetEntry, now: datetime) -> FleetVehicleOut:
    """The API view of a fleet entry."""
    vehicle = entry.vehicle
    ping = entry.last_ping
    status = entry.last_status
    return FleetVehicleOut(
        vehicle_id=vehicle.vehicle_id,
        make=vehicle.make,
        model=vehicle.model,
        year=vehicle.year,
        actuation=vehicle.actuation,
        corridor_id=vehicle.corridor_id,
        route=vehicle.route,
        assigned_lane=vehicle.assigned_lane,
        controller=ControllerAssignment(
            name=vehicle.controller_name, params=dict(vehicle.controller_params)
        ),
        config_version=vehicle.config_version,
        active=vehicle.is_active,
        in_maintenance=vehicle.is_in_maintenance,
        maintenance_note=vehicle.maintenance_note,
        last_ping=None
        if ping is None
        else PingOut(
            ts=ping.ts,
            received_at=ping.received_at,
            age_s=entry.message_age_s(ping.ts, ping.received_at, now),
            speed_mps=ping.speed_mps,
            x_m=ping.x_m,
            postmile=entry.postmile,
            corridor_id=entry.ping_corridor_id,
            lane=ping.lane,
            acc_engaged=ping.is_acc_engaged,
            controller_engaged=ping.is_controller_engaged,
            controller=ping.controller,
            plan_id=ping.plan_id,
            policy_sha256=ping.policy_sha256,
        ),
        last_status=None
        if status is None
        else StatusOut(
            ts=status.ts,
            received_at=status.received_at,
            age_s=entry.message_age_s(status.ts, status.received_at, now),
            agent_version=status.agent_version,
            uptime_s=status.uptime_s,
            can_ok=status.is_can_ok,
            can_msgs_per_s=status.can_msgs_per_s,
            gps_fix=status.has_gps_fix,
            gps_satellites=status.gps_satellites,
            acc_available=status.is_acc_available,
            controller=status.controller,
            controller_running=status.is_controller_running,
            plan_id=status.plan_id,
            plan_age_s=status.plan_age_s,
            spool_backlog=status.spool_backlog,
            spool_dropped=status.spool_dropped,
            disk_free_mb=status.disk_free_mb,
            cpu_temp_c=status.cpu_temp_c,
            ups_on_battery=status.is_ups_on_battery,
            server_rtt_ms=status.server_rtt_ms,
            policy_sha256=status.policy_sha256,
            engage_reason=status.engage_reason,
        ),
        checks=[
            CheckOut(
                name=check.name,
                label=check.label,
                level=check.level,
                value=check.value,
                detail=check.detail,
                reason=check.reason,
                pending=check.pending,
            )
            for check in entry.readiness.checks
        ],
        verdict=entry.readiness.verdict,
        cleared=entry.readiness.is_cleared,
        problems=list(entry.readiness.problems),
    )


def counts_out(counts: FleetCounts) -> FleetCountsOut:
    """The API view of the counts."""
    return FleetCountsOut(
        vehicles=counts.vehicles,
        cleared=counts.cleared,
        not_cleared=counts.not_cleared,
        maintenance=counts.maintenance,
        inactive=counts.inactive,
        reporting=counts.reporting,
        engaged=counts.engaged,
    )
