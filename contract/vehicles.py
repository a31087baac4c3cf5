"""What a vehicle posts and reads (docs/interfaces.md, "Vehicles"): its pings, its status
report, and the config it runs. The server validates with these models and the agent builds its
messages with them, so the two cannot drift apart.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, StrictBool, field_validator

from contract.controllers import POLICY_SHA256_PATTERN
from contract.values import JsonFloat, Text64, Text120, Timestamp, json_number, real

VEHICLE_ID_PATTERN = r"^[A-Za-z0-9_-]{1,32}$"
# A car holds its plan this long after publication by default, then hands the car back; the
# server's planner publishes every 60 s, so two skipped cycles still keep a car on its plan.
STALE_PLAN_AFTER_S = 180.0
# The longest agent periods a config may set (s). A period is when the agent next does the job,
# set once from the config: a config's 1e300 (or Infinity) stopped pings, status reports or
# plan polls for the rest of the run, the corrected config never reaching the schedule.
MAX_PING_PERIOD_S = 60.0
MAX_STATUS_PERIOD_S = 600.0
MAX_PLAN_POLL_S = 600.0
MAX_STALE_PLAN_AFTER_S = 86_400.0
# A batch is the agent's store-and-forward upload: at most this many pings per request.
MAX_PINGS_PER_BATCH = 1000
# Plan ids stay below 2^53: every JSON reader (IEEE doubles) holds them exactly.
MAX_JSON_INTEGER = 2**53 - 1
# The rule on a report's time that JSON Schema cannot state (it is relative to the server's
# clock): the server keeps reports as long as pings, and a car's GPS clock is never far ahead.
REPORT_TIME_WINDOW = (
    "The car's clock. Must lie within the server's window around its own clock: at most "
    "SMOOTHFLEET_PING_RETENTION_DAYS (default 90) days behind and SMOOTHFLEET_PING_MAX_FUTURE_S "
    "(default 300) s ahead; a report outside it is refused with 422 and not stored."
)


# The header of every answer to a known vehicle's plan poll (`GET /api/v1/vehicles/{id}/plan`:
# 200, 304, 503 `no_valid_plan` and 404 for a lane its corridor lacks) naming the vehicle's
# `config_version` now: a car running another fetches its config at once instead of at its
# next refresh (docs/interfaces.md).
CONFIG_VERSION_HEADER = "X-Config-Version"


class Ping(BaseModel):
    """One 1 Hz ping of a vehicle; `ts` is the car's GPS-disciplined clock.

    Unknown fields are ignored, so a newer agent may send fields this server does not know yet.
    Lane and the time window are checked against the corridor and the clock at ingest.
    Every float's range lies well inside a REAL column's, and the ingest's binary COPY stores a
    magnitude a REAL cannot hold as 0, so pings need no `real` check (status and INRIX, written
    through SQL parameters, do).
    """

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    vehicle_id: str = Field(pattern=VEHICLE_ID_PATTERN)
    ts: Timestamp
    lat: JsonFloat = Field(ge=-90, le=90)
    lon: JsonFloat = Field(ge=-180, le=180)
    speed_mps: JsonFloat = Field(ge=0, le=90)
    accel_mps2: JsonFloat | None = Field(None, ge=-50, le=50)
    heading_deg: JsonFloat | None = Field(None, ge=0, le=360)
    lane: int | None = Field(None, ge=1, le=12)
    acc_engaged: StrictBool | None = None
    controller_engaged: StrictBool | None = None
    controller: Text64 | None = None
    acc_speed_setting_mph: JsonFloat | None = Field(None, ge=0, le=200)
    acc_gap_setting: int | None = Field(None, ge=1, le=3)
    lead_present: StrictBool | None = Field(None, description="the car's 'minicar' lead flag")
    lead_distance_m: JsonFloat | None = Field(None, ge=0, le=1000)
    lead_rel_speed_mps: JsonFloat | None = Field(None, ge=-90, le=90)
    plan_id: int | None = Field(None, ge=0, le=MAX_JSON_INTEGER)
    policy_sha256: str | None = Field(
        None, pattern=POLICY_SHA256_PATTERN, description="the policy the controller runs"
    )
    config_version: int | None = Field(
        None,
        ge=1,
        le=2**31 - 1,
        description="the version of the vehicle's config the car held when it took the ping",
    )

    _integers = field_validator(
        "lane", "acc_gap_setting", "plan_id", "config_version", mode="before"
    )(json_number)


class PingBatch(BaseModel):
    """The store-and-forward upload: up to 1000 pings in one request."""

    pings: list[Ping] = Field(max_length=MAX_PINGS_PER_BATCH)


class Rejection(BaseModel):
    """A ping refused on its own (the others of its batch are kept).

    `retryable` marks a refusal the same ping may pass unchanged later, because what it was
    judged against can change: the server's clock (a `ts` "in the future" from a server whose
    clock is behind) or its roster (a vehicle not on it yet). The car keeps such a ping and
    sends it again; every other rejection is final. Absent (an older server): final."""

    index: int
    error: str
    retryable: bool = False


class PingAnswer(BaseModel):
    """Sent only after the accepted rows are committed. Counts are never negative: a car sums
    them with the rejections to check every ping of its batch is answered for once."""

    accepted: int = Field(ge=0)
    duplicates: int = Field(ge=0)
    conflicts: int = Field(
        0,
        ge=0,
        description="of the duplicates, those that said something else than the ping already "
        "kept at their vehicle_id and ts (a clock stamping two pings alike): not stored, the "
        "first kept; absent (an older server): 0",
    )
    rejected: list[Rejection]


class VehicleStatusReport(BaseModel):
    """The piStatus report a car posts every ~10 s (all but `ts` optional)."""

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    ts: Timestamp = Field(description=REPORT_TIME_WINDOW)
    agent_version: Text64 | None = None
    uptime_s: JsonFloat | None = Field(None, ge=0, le=1e10)  # ~300 years
    can_ok: StrictBool | None = None
    can_msgs_per_s: JsonFloat | None = Field(None, ge=0, le=1e7)
    gps_fix: StrictBool | None = None
    gps_satellites: int | None = Field(None, ge=0, le=255)
    acc_available: StrictBool | None = None
    controller: Text64 | None = None
    controller_running: StrictBool | None = None
    plan_id: int | None = Field(None, ge=0, le=MAX_JSON_INTEGER)
    plan_age_s: JsonFloat | None = Field(None, ge=0, le=1e10)
    spool_backlog: int | None = Field(None, ge=0, le=2**31 - 1)
    spool_dropped: int | None = Field(
        None,
        ge=0,
        le=2**31 - 1,
        description="pings the car's spool dropped unsent because it was full, in all since "
        "the spool file was made",
    )
    disk_free_mb: JsonFloat | None = Field(None, ge=0, le=1e12)
    cpu_temp_c: JsonFloat | None = Field(None, ge=-60, le=150)
    ups_on_battery: StrictBool | None = None
    server_rtt_ms: JsonFloat | None = Field(None, ge=0, le=1e9)
    config_version: int | None = Field(
        None, ge=1, le=2**31 - 1, description="the vehicle config version the agent runs"
    )
    policy_sha256: str | None = Field(
        None, pattern=POLICY_SHA256_PATTERN, description="the policy the controller runs"
    )
    engage_reason: Text120 | None = Field(
        None,
        description="why the agent commands the car or leaves it to its stock ACC, in the "
        "agent's words ('engaged', 'no fresh plan', 'controller failed', ...)",
    )

    _integers = field_validator(
        "gps_satellites",
        "plan_id",
        "spool_backlog",
        "spool_dropped",
        "config_version",
        mode="before",
    )(json_number)
    _real = field_validator(
        "can_msgs_per_s", "plan_age_s", "disk_free_mb", "cpu_temp_c", "server_rtt_ms"
    )(real)


class StatusAnswer(BaseModel):
    """1 stored, or 0 and 1 duplicate when the same report (vehicle, ts) was already stored."""

    accepted: int
    duplicates: int


class ControllerConfig(BaseModel):
    """Which controller the agent runs, and its parameters (schemas: `contract.controllers`)."""

    name: str
    params: dict[str, Any] = Field(default_factory=dict)


class VehicleConfig(BaseModel):
    """What a vehicle should run: its identity, assignment, controller and agent periods.

    Unknown fields are ignored, so a car keeps reading the configs of a newer server.
    """

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False)

    vehicle_id: str
    make: str
    model: str
    year: int
    actuation: Literal["acc", "accel"]
    corridor_id: str
    route: str
    assigned_lane: int = Field(ge=1)
    controller: ControllerConfig
    active: bool = Field(True, description="false: the agent leaves the car to its stock ACC")
    in_maintenance: bool = False
    ping_period_s: float = Field(1.0, gt=0, le=MAX_PING_PERIOD_S)
    status_period_s: float = Field(10.0, gt=0, le=MAX_STATUS_PERIOD_S)
    plan_poll_s: float = Field(5.0, gt=0, le=MAX_PLAN_POLL_S)
    stale_plan_after_s: float = Field(STALE_PLAN_AFTER_S, gt=0, le=MAX_STALE_PLAN_AFTER_S)
    config_version: int | None = Field(
        None, ge=1, description="bumped by every change; echoed in the car's status reports"
    )
