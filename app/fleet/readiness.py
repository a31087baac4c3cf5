"""Readiness checks of a vehicle (the paper's piStatus): green, amber or red, and a verdict.

Headquarters cleared each car for deployment on piStatus and watched it during the experiment
for hardware problems (paper, "Vehicle-side implementation"). Each check here reads the car's
last ping and last status report and grades one thing against thresholds from the settings
(`SMOOTHFLEET_READINESS_*`). A car is cleared when it is active, not in maintenance, and no
check is red; amber checks are warnings an operator should look at.

Adding a check is one function and one entry in CHECKS.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime
from typing import Literal

from app.core.config import Settings

Level = Literal["green", "amber", "red", "unknown"]
Verdict = Literal["cleared", "not cleared", "maintenance", "inactive"]


@dataclass(frozen=True)
class Thresholds:
    """(amber, red) per graded quantity; see Settings.readiness_*."""

    ping_age_s: tuple[float, float]
    status_age_s: tuple[float, float]
    plan_age_s: tuple[float, float]
    spool_backlog: tuple[float, float]
    cpu_temp_c: tuple[float, float]
    disk_free_mb: tuple[float, float]
    can_msgs_per_s: tuple[float, float]
    gps_satellites: tuple[float, float]
    agent_version: str | None

    @classmethod
    def from_settings(cls, settings: Settings) -> Thresholds:
        """The thresholds configured for this server."""
        return cls(
            ping_age_s=settings.readiness_ping_age_s,
            status_age_s=settings.readiness_status_age_s,
            plan_age_s=settings.readiness_plan_age_s,
            spool_backlog=settings.readiness_spool_backlog,
            cpu_temp_c=settings.readiness_cpu_temp_c,
            disk_free_mb=settings.readiness_disk_free_mb,
            can_msgs_per_s=settings.readiness_can_msgs_per_s,
            gps_satellites=settings.readiness_gps_satellites,
            agent_version=settings.readiness_agent_version,
        )


@dataclass(frozen=True)
class LastPing:
    """The newest ping of a vehicle (by its GPS time)."""

    ts: datetime
    received_at: datetime
    speed_mps: float
    x_m: float | None
    lane: int | None
    is_acc_engaged: bool | None
    is_controller_engaged: bool | None
    controller: str | None
    plan_id: int | None


@dataclass(frozen=True)
class LastStatus:
    """The newest status report of a vehicle (fields as in fact_vehicle_status)."""

    ts: datetime
    received_at: datetime
    agent_version: str | None = None
    uptime_s: float | None = None
    is_can_ok: bool | None = None
    can_msgs_per_s: float | None = None
    has_gps_fix: bool | None = None
    gps_satellites: int | None = None
    is_acc_available: bool | None = None
    controller: str | None = None
    is_controller_running: bool | None = None
    plan_id: int | None = None
    plan_age_s: float | None = None
    spool_backlog: int | None = None
    disk_free_mb: float | None = None
    cpu_temp_c: float | None = None
    is_ups_on_battery: bool | None = None
    server_rtt_ms: float | None = None


@dataclass(frozen=True)
class VehicleFacts:
    """What the checks look at: the roster row's state and the last ping and status."""

    vehicle_id: str
    assigned_controller: str
    is_active: bool
    is_in_maintenance: bool
    last_ping: LastPing | None
    last_status: LastStatus | None


@dataclass(frozen=True)
class CheckResult:
    """One graded check: `value` is what the car reported, `detail` why it got its level."""

    name: str
    label: str
    level: Level
    value: str
    detail: str


@dataclass(frozen=True)
class Readiness:
    """All checks of a vehicle and the deployment verdict."""

    checks: tuple[CheckResult, ...]
    verdict: Verdict
    problems: tuple[str, ...]

    @property
    def is_cleared(self) -> bool:
        """True when the vehicle may be deployed."""
        return self.verdict == "cleared"

    def level_of(self, name: str) -> Level:
        """The level of the named check."""
        for check in self.checks:
            if check.name == name:
                return check.level
        raise KeyError(name)


def grade_rising(value: float, band: tuple[float, float]) -> Level:
    """Amber at or above band[0], red at or above band[1] (ages, backlog, temperature)."""
    amber, red = band
    if value >= red:
        return "red"
    if value >= amber:
        return "amber"
    return "green"


def grade_falling(value: float, band: tuple[float, float]) -> Level:
    """Amber at or below band[0], red at or below band[1] (disk, CAN rate, satellites)."""
    amber, red = band
    if value <= red:
        return "red"
    if value <= amber:
        return "amber"
    return "green"


def describe_age(seconds: float) -> str:
    """An age for people: 12 s, 4 min, 3 h, 2 d."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


Evaluate = Callable[[VehicleFacts, datetime, Thresholds], tuple[Level, str, str]]


def _unknown(what: str) -> tuple[Level, str, str]:
    return "unknown", "—", f"the car did not report {what}"


def check_ping(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """Age of the newest ping (the car's GPS time)."""
    if facts.last_ping is None:
        return "red", "never", "no ping received"
    age = (now - facts.last_ping.ts).total_seconds()
    level = grade_rising(age, limits.ping_age_s)
    amber, red = limits.ping_age_s
    return level, describe_age(age), f"amber from {amber:g} s, red from {red:g} s"


def check_status(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """Age of the newest status report (sent every ~10 s by a healthy agent)."""
    if facts.last_status is None:
        return "red", "never", "no status report received"
    age = (now - facts.last_status.ts).total_seconds()
    level = grade_rising(age, limits.status_age_s)
    amber, red = limits.status_age_s
    return level, describe_age(age), f"amber from {amber:g} s, red from {red:g} s"


def check_gps(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """GPS fix and satellites in view."""
    status = facts.last_status
    if status is None or status.has_gps_fix is None:
        return _unknown("its GPS fix")
    satellites = status.gps_satellites
    shown = f"{satellites} sat" if satellites is not None else ""
    if not status.has_gps_fix:
        return "red", ("no fix " + shown).strip(), "no GPS fix: no position, no clock sync"
    if satellites is None:
        return "green", "fix", "fix (satellites not reported)"
    amber, red = limits.gps_satellites
    level = grade_falling(satellites, limits.gps_satellites)
    return level, f"fix, {shown}", f"amber at {amber:g} satellites or fewer, red at {red:g}"


def check_can(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """CAN bus readable, and the rate of frames received."""
    status = facts.last_status
    if status is None or (status.is_can_ok is None and status.can_msgs_per_s is None):
        return _unknown("its CAN bus")
    if status.is_can_ok is False:
        return "red", "down", "the agent cannot read the car's CAN bus"
    if status.can_msgs_per_s is None:
        return "green", "ok", "CAN ok (rate not reported)"
    amber, red = limits.can_msgs_per_s
    level = grade_falling(status.can_msgs_per_s, limits.can_msgs_per_s)
    detail = f"amber at {amber:g}/s or less, red at {red:g}/s"
    return level, f"{status.can_msgs_per_s:.0f}/s", detail


def check_acc(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """The car's adaptive cruise control is available to the controller."""
    status = facts.last_status
    if status is None or status.is_acc_available is None:
        return _unknown("ACC availability")
    if status.is_acc_available:
        return "green", "yes", "ACC available"
    return "red", "no", "ACC not available: the controller cannot act"


def check_controller(
    facts: VehicleFacts, now: datetime, limits: Thresholds
) -> tuple[Level, str, str]:
    """The assigned controller runs."""
    status = facts.last_status
    if status is None or status.is_controller_running is None:
        return _unknown("its controller")
    name = status.controller or "?"
    if not status.is_controller_running:
        return "red", f"{name} stopped", "the controller is not running"
    if status.controller is not None and status.controller != facts.assigned_controller:
        return (
            "amber",
            f"{name} runs",
            f"runs {name}, assigned {facts.assigned_controller} (config not picked up yet?)",
        )
    return "green", f"{name} runs", "the assigned controller runs"


def check_plan(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """Age of the speed plan the car holds (it falls back to stock ACC when it is stale)."""
    status = facts.last_status
    if status is None:
        return _unknown("its plan")
    if status.plan_age_s is None:
        return "amber", "none", "no plan held: the car drives on stock ACC"
    amber, red = limits.plan_age_s
    level = grade_rising(status.plan_age_s, limits.plan_age_s)
    return level, describe_age(status.plan_age_s), f"amber from {amber:g} s, red from {red:g} s"


def check_spool(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """Pings waiting on the car for upload (store and forward)."""
    status = facts.last_status
    if status is None or status.spool_backlog is None:
        return _unknown("its spool backlog")
    amber, red = limits.spool_backlog
    level = grade_rising(status.spool_backlog, limits.spool_backlog)
    return level, str(status.spool_backlog), f"amber from {amber:g}, red from {red:g} pings"


def check_disk(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """Free disk on the car's computer (recordings and the spool)."""
    status = facts.last_status
    if status is None or status.disk_free_mb is None:
        return _unknown("its free disk")
    amber, red = limits.disk_free_mb
    level = grade_falling(status.disk_free_mb, limits.disk_free_mb)
    return level, f"{status.disk_free_mb:.0f} MB", f"amber at {amber:g} MB or less, red at {red:g}"


def check_temperature(
    facts: VehicleFacts, now: datetime, limits: Thresholds
) -> tuple[Level, str, str]:
    """CPU temperature (a Raspberry Pi throttles from about 80 °C)."""
    status = facts.last_status
    if status is None or status.cpu_temp_c is None:
        return _unknown("its temperature")
    amber, red = limits.cpu_temp_c
    level = grade_rising(status.cpu_temp_c, limits.cpu_temp_c)
    return level, f"{status.cpu_temp_c:.0f} °C", f"amber from {amber:g} °C, red from {red:g} °C"


def check_agent(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """The agent version, against the one every car should run (if configured)."""
    status = facts.last_status
    if status is None or status.agent_version is None:
        return _unknown("its agent version")
    expected = limits.agent_version
    if expected is not None and status.agent_version != expected:
        return "amber", status.agent_version, f"expected {expected}: update over the air"
    return "green", status.agent_version, "agent version as expected"


def check_power(facts: VehicleFacts, now: datetime, limits: Thresholds) -> tuple[Level, str, str]:
    """On UPS battery means the car was switched off (the computer uploads and shuts down)."""
    status = facts.last_status
    if status is None or status.is_ups_on_battery is None:
        return _unknown("its power source")
    if status.is_ups_on_battery:
        return "amber", "battery", "on UPS battery: the car is switched off"
    return "green", "car", "powered by the car"


@dataclass(frozen=True)
class Check:
    """A named check and how to grade it."""

    name: str
    label: str
    evaluate: Evaluate


CHECKS: tuple[Check, ...] = (
    Check("ping", "last ping", check_ping),
    Check("status", "last status", check_status),
    Check("gps", "GPS", check_gps),
    Check("can", "CAN", check_can),
    Check("acc", "ACC", check_acc),
    Check("controller", "controller", check_controller),
    Check("plan", "plan age", check_plan),
    Check("spool", "spool", check_spool),
    Check("disk", "disk free", check_disk),
    Check("temperature", "CPU temp", check_temperature),
    Check("agent", "agent", check_agent),
    Check("power", "power", check_power),
)
CHECK_NAMES = tuple(check.name for check in CHECKS)


def assess(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Readiness:
    """Grade every check and decide whether the vehicle is cleared for deployment."""
    results = []
    for check in CHECKS:
        level, value, detail = check.evaluate(facts, now, limits)
        results.append(CheckResult(check.name, check.label, level, value, detail))
    problems = tuple(f"{r.label}: {r.detail}" for r in results if r.level == "red")
    verdict: Verdict
    if not facts.is_active:
        verdict = "inactive"
    elif facts.is_in_maintenance:
        verdict = "maintenance"
    elif problems:
        verdict = "not cleared"
    else:
        verdict = "cleared"
    return Readiness(tuple(results), verdict, problems)
