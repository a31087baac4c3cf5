"""Readiness checks of a vehicle (the paper's piStatus): green, amber or red, and a verdict.

Headquarters cleared each car for deployment on piStatus and watched it during the experiment
for hardware problems (paper, "Vehicle-side implementation"). Each check here reads the car's
last ping and last status report and grades one thing against thresholds from the settings
(`SMOOTHFLEET_READINESS_*`); the CAN rate is graded against the car's own make (its CAN
schedule). A car is cleared when it is active, not in maintenance, and no check is red; amber
checks are warnings an operator should look at. A check that is not green says why in words
(`reason`: "CAN 19/s < 45/s for Rogue", "plan 212 s old").

Hysteresis: the checks graded from status reports change level only when the new level has held
over every report for `hold_s` (SMOOTHFLEET_READINESS_HOLD_S), so one slow report from a busy
server or a loaded car never flips a verdict. The level is replayed from the reports of the last
few hold periods (from the worst of the oldest period, `hold_levels`), so every server process and
every restart agree. The two age checks (last
ping, last status) need no hold: an age is itself a time held; they are measured against the
wall clock less the server's own ingest lag (app.fleet.service), so a server that falls behind
ages no car.

Adding a check is one function and one entry in CHECKS.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
from typing import Literal, NamedTuple

from app.core.config import Settings
from vehicle_agent.cars import CARS

Level = Literal["green", "amber", "red", "unknown"]
Verdict = Literal["cleared", "not cleared", "maintenance", "inactive"]

# Status reports replayed for hysteresis: this many hold periods back from the newest report;
# all but the last two only settle the level to start from (hold_levels).
HOLD_PERIODS_REPLAYED = 3

# Levels from best to worst; hysteresis compares levels by this order.
SEVERITY: dict[Level, int] = {"green": 0, "unknown": 1, "amber": 2, "red": 3}


@dataclass(frozen=True)
class CanSchedule:
    """The frames per second a make's car sends the agent, by the car's own message periods.

    Source: the periods of the messages the agent watches, in the make's table in
    `vehicle_agent.cars` (nissan_canfd.py, gm.py, toyota.py, nissan.py: e.g. the 2023 Rogue's
    speed every 20 ms and its cruise state, buttons and HUD every 100 ms, 80 frames/s in all; the
    2018-20 Rogue's 150). No DBC here carries GenMsgCycleTime (cantools reads `cycle_time`
    None for all 15 opendbc messages, and the field team's Rogue DBC has none), and the recorded
    sample in ../shared/data/can has whole-second timestamps over a decimated stream (948 frames
    of SPEED in 63 s, where the RAV4 sends 50/s), so neither can replace the table.
    """

    model: str
    scheduled_per_s: float

    @classmethod
    def of_make(cls, make: str, model: str, year: int | None = None) -> CanSchedule | None:
        """The schedule of the car of this make, model and year (without a year: the fleet's
        car of that make and model), or None for an unknown car."""
        for car in CARS.values():
            if year is not None and year not in car.years:
                continue
            if car.make.lower() == make.lower() and car.model.lower() == model.lower():
                rate = sum(1.0 / rule.period_s for rule in car.messages.values())
                return cls(car.model, rate)
        return None


@dataclass(frozen=True)
class Thresholds:
    """(amber, red) per graded quantity; see Settings.readiness_*."""

    ping_age_s: tuple[float, float]
    status_age_s: tuple[float, float]
    plan_age_s: tuple[float, float]
    spool_backlog: tuple[float, float]
    cpu_temp_c: tuple[float, float]
    disk_free_mb: tuple[float, float]
    can_share: tuple[float, float]
    gps_satellites: tuple[float, float]
    agent_version: str | None
    hold_s: float = 0.0
    server_lag_s: float = 0.0

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
            can_share=settings.readiness_can_share,
            gps_satellites=settings.readiness_gps_satellites,
            agent_version=settings.readiness_agent_version,
            hold_s=settings.readiness_hold_s,
            server_lag_s=settings.readiness_server_lag_s,
        )

    def can_rates(self, schedule: CanSchedule) -> tuple[float, float]:
        """(amber, red) frames per second for a make: shares of its scheduled rate."""
        amber, red = self.can_share
        return amber * schedule.scheduled_per_s, red * schedule.scheduled_per_s


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
    policy_sha256: str | None = None


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
    spool_dropped: int | None = None
    disk_free_mb: float | None = None
    cpu_temp_c: float | None = None
    is_ups_on_battery: bool | None = None
    server_rtt_ms: float | None = None
    policy_sha256: str | None = None
    engage_reason: str | None = None
    config_version: int | None = None


@dataclass(frozen=True)
class VehicleFacts:
    """What the checks look at: the roster row's state and the last ping and status."""

    vehicle_id: str
    assigned_controller: str
    is_active: bool
    is_in_maintenance: bool
    last_ping: LastPing | None
    last_status: LastStatus | None
    make: str = ""
    model: str = ""
    year: int | None = None
    # The reports before last_status in the hysteresis window, oldest first.
    earlier_statuses: tuple[LastStatus, ...] = ()
    # The roster's config version: the agent echoes the one it runs (None: not compared).
    config_version: int | None = None
    # How far behind the server stores what the fleet sends (`app.fleet.service._server_lag_s`),
    # by which the checks' `now` is set back: what this car sent is never younger than the time
    # since the server stored it (`message_age_s`).
    server_lag_s: float = 0.0


@dataclass(frozen=True)
class CheckResult:
    """One graded check: `value` is what the car reported, `detail` its thresholds, `reason` why
    it is not green in words (empty when green), `pending` a level change waiting out its hold."""

    name: str
    label: str
    level: Level
    value: str
    detail: str
    reason: str = ""
    pending: str = ""


@dataclass(frozen=True)
class Readiness:
    """All checks of a vehicle and the deployment verdict."""

    checks: tuple[CheckResult, ...]
    verdict: Verdict
    problems: tuple[str, ...]  # the reasons of the red checks

    @property
    def reasons(self) -> tuple[str, ...]:
        """Why the car is not cleared (or what to look at), worst first, in words."""
        shown = [c for c in self.checks if c.level in ("red", "amber")]
        shown.sort(key=lambda c: -SEVERITY[c.level])
        return tuple(c.reason for c in shown)

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
    """An age for people: 212 s, 14 min, 3 h, 2 d (seconds up to ten minutes: a plan's age
    matters to the second around its 180 s limit)."""
    if seconds < 600:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.0f} h"
    return f"{seconds / 86400:.0f} d"


class Grade(NamedTuple):
    """A check's answer for one moment: level, the value shown, thresholds, reason in words."""

    level: Level
    value: str
    detail: str
    reason: str = ""


Evaluate = Callable[[VehicleFacts, datetime, Thresholds], Grade]


def _unknown(label: str, what: str) -> Grade:
    return Grade("unknown", "—", f"the car did not report {what}", f"{label} not reported")


def _unreported(label: str, what: str) -> Grade:
    """A status report that leaves out what a car needs to drive (its GPS fix, its CAN bus, its
    ACC): red, since a car is cleared on what it said, not on what it did not."""
    return Grade("red", "—", f"the car's status did not report {what}", f"{label} not reported")


def _sent_at(ts: datetime, received_at: datetime) -> datetime:
    """When a message was sent: by the car's time, but never later than the server received it.
    A car whose clock runs ahead (the server accepts up to 300 s) would otherwise show a negative
    age, green, and stay green that much longer after it fell silent."""
    return min(ts, received_at)


def message_age_s(
    ts: datetime, received_at: datetime, now: datetime, server_lag_s: float = 0.0
) -> float:
    """How long ago a message was sent (`_sent_at`), never negative: what the age checks
    grade and what the fleet's answer shows. `now` is set back by the server's lag, which
    the fleet's delays measure; but never younger than the time since the server stored it
    (`now` + the lag is the server's own clock). The lag is the least delay of the cars that
    reported lately, and with one car reporting, that car's own: a car whose clock is behind,
    or one uploading a backlog, set it for all, and a car silent for 151 s showed 41 s, and
    cleared."""
    sent = (now - _sent_at(ts, received_at)).total_seconds()
    stored = (now - received_at).total_seconds() + server_lag_s
    return max(sent, stored, 0.0)


def check_ping(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """Age of the newest ping (the car's GPS time)."""
    if facts.last_ping is None:
        return Grade("red", "never", "no ping received", "never pinged")
    ping = facts.last_ping
    age = message_age_s(ping.ts, ping.received_at, now, facts.server_lag_s)
    level = grade_rising(age, limits.ping_age_s)
    amber, red = limits.ping_age_s
    return Grade(
        level,
        describe_age(age),
        f"amber from {amber:g} s, red from {red:g} s",
        f"no ping for {describe_age(age)}",
    )


def check_status(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """Age of the newest status report (sent every ~10 s by a healthy agent)."""
    if facts.last_status is None:
        return Grade("red", "never", "no status report received", "never reported its status")
    status = facts.last_status
    age = message_age_s(status.ts, status.received_at, now, facts.server_lag_s)
    level = grade_rising(age, limits.status_age_s)
    amber, red = limits.status_age_s
    return Grade(
        level,
        describe_age(age),
        f"amber from {amber:g} s, red from {red:g} s",
        f"no status for {describe_age(age)}",
    )


def check_gps(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """GPS fix and satellites in view."""
    status = facts.last_status
    if status is None:
        return _unknown("GPS", "its GPS fix")
    if status.has_gps_fix is None:
        return _unreported("GPS", "its GPS fix")
    satellites = status.gps_satellites
    shown = f"{satellites} sat" if satellites is not None else ""
    if not status.has_gps_fix:
        return Grade(
            "red",
            ("no fix " + shown).strip(),
            "no GPS fix: no position, no clock sync",
            "no GPS fix",
        )
    if satellites is None:
        return Grade("green", "fix", "fix (satellites not reported)")
    amber, red = limits.gps_satellites
    level = grade_falling(satellites, limits.gps_satellites)
    return Grade(
        level,
        f"fix, {shown}",
        f"amber at {amber:g} satellites or fewer, red at {red:g}",
        f"GPS {satellites} satellites ≤ {red if level == 'red' else amber:g}",
    )


def check_can(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """CAN bus readable, and the rate of frames received against the make's own schedule."""
    status = facts.last_status
    if status is None:
        return _unknown("CAN", "its CAN bus")
    if status.is_can_ok is None and status.can_msgs_per_s is None:
        return _unreported("CAN", "its CAN bus")
    if status.is_can_ok is False:
        return Grade("red", "down", "the agent cannot read the car's CAN bus", "CAN down")
    if status.can_msgs_per_s is None:
        return Grade("green", "ok", "CAN ok (rate not reported)")
    rate = status.can_msgs_per_s
    schedule = CanSchedule.of_make(facts.make, facts.model, facts.year)
    if schedule is None:
        return Grade(
            "amber",
            f"{rate:.0f}/s",
            f"no CAN schedule for a {facts.make} {facts.model} {facts.year or ''}".rstrip(),
            f"CAN rate unknown for {facts.make} {facts.model}",
        )
    amber, red = limits.can_rates(schedule)
    level = grade_falling(rate, (amber, red))
    detail = (
        f"the {schedule.model} sends {schedule.scheduled_per_s:.0f}/s: "
        f"amber at {amber:.0f}/s or less, red at {red:.0f}/s"
    )
    bound = red if level == "red" else amber
    return Grade(
        level, f"{rate:.0f}/s", detail, f"CAN {rate:.0f}/s ≤ {bound:.0f}/s for {schedule.model}"
    )


def check_acc(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """The car's adaptive cruise control is available to the controller."""
    status = facts.last_status
    if status is None or (status.is_acc_available is None and status.is_can_ok is False):
        # no report, or no CAN to read it from: the status or CAN check says why
        return _unknown("ACC", "ACC availability")
    if status.is_acc_available is None:
        return _unreported("ACC", "ACC availability")
    if status.is_acc_available:
        return Grade("green", "yes", "ACC available")
    return Grade("red", "no", "ACC not available: the controller cannot act", "ACC not available")


def check_controller(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """The car runs the assigned controller.

    The agent reports its controller as running only while it drives the car (engaged:
    vehicle_agent/agent.py `controller_running`), so "not running" is every parked car at
    6 a.m. and every car its driver has not engaged yet: a warning, never a reason to withhold
    clearance. An agent that reports no controller at all built none from its assignment (a
    policy it refused or could not fetch, no config yet): that car cannot be driven, and is red.
    """
    status = facts.last_status
    if status is None or status.is_controller_running is None:
        return _unknown("controller", "its controller")
    if status.controller is None and not status.is_controller_running:
        # The agent built no controller from its assignment (a policy refused or not fetched,
        # no config yet): it cannot drive the car, however healthy the rest.
        why = f": {status.engage_reason}" if status.engage_reason else ""
        return Grade(
            "red",
            "none",
            f"the agent runs no controller (assigned {facts.assigned_controller}{why})",
            f"no controller built for {facts.assigned_controller}{why}",
        )
    name = status.controller or facts.assigned_controller
    if (
        status.config_version is not None
        and facts.config_version is not None
        and status.config_version != facts.config_version
    ):
        # the car still runs an assignment it was given before (a lane, a controller, a
        # policy): the agent reads its config every 60 s, so this lasts a minute at most
        # unless the new one cannot be adopted
        return Grade(
            "amber",
            f"{name} {'runs' if status.is_controller_running else 'idle'}",
            f"runs config v{status.config_version}, assigned v{facts.config_version}",
            f"runs config v{status.config_version}, assigned v{facts.config_version}"
            " (not picked up yet?)",
        )
    if status.controller is not None and status.controller != facts.assigned_controller:
        return Grade(
            "amber",
            f"{name} {'runs' if status.is_controller_running else 'idle'}",
            f"runs {name}, assigned {facts.assigned_controller} (config not picked up yet?)",
            f"runs {name}, assigned {facts.assigned_controller}",
        )
    if not status.is_controller_running:
        # the agent says why (its engage check that failed), so the operator is pointed at the
        # part at fault: the driver, the GPS, the plan, the buttons, the CAN bus
        why = f": {status.engage_reason}" if status.engage_reason else ""
        return Grade(
            "amber",
            f"{name} idle",
            f"the controller is not driving the car (not engaged{why})",
            f"controller {name} not engaged{why}",
        )
    return Grade("green", f"{name} runs", "the assigned controller drives the car")


def check_plan(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """Age of the speed plan the car holds (it falls back to stock ACC when it is stale).

    The car measured the age when it sent the report; the plan has aged since as far as the
    server knows: a report sent 60 s ago that said 10 s is a plan 70 s old now. Read as it was
    sent, a car that fell silent with a fresh plan showed that plan fresh for ever.
    """
    status = facts.last_status
    if status is None:
        return _unknown("plan", "its plan")
    if status.plan_age_s is None:
        return Grade("amber", "none", "no plan held: the car drives on stock ACC", "no plan held")
    amber, red = limits.plan_age_s
    age_s = status.plan_age_s + message_age_s(
        status.ts, status.received_at, now, facts.server_lag_s
    )
    level = grade_rising(age_s, limits.plan_age_s)
    age = describe_age(age_s)
    return Grade(level, age, f"amber from {amber:g} s, red from {red:g} s", f"plan {age} old")


def check_spool(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """Pings waiting on the car for upload (store and forward)."""
    status = facts.last_status
    if status is None or status.spool_backlog is None:
        return _unknown("spool", "its spool backlog")
    amber, red = limits.spool_backlog
    level = grade_rising(status.spool_backlog, limits.spool_backlog)
    # Pings the full spool dropped are lost to the warehouse; said here, not graded: the total
    # counts since the spool was made, and a car that dropped some on an old outage is fit now.
    dropped = f", {status.spool_dropped} dropped unsent" if status.spool_dropped else ""
    return Grade(
        level,
        f"{status.spool_backlog}{dropped}",
        f"amber from {amber:g}, red from {red:g} pings waiting; dropped: since the car's "
        "spool was made",
        f"{status.spool_backlog} pings waiting to upload{dropped}",
    )


def check_disk(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """Free disk on the car's computer (recordings and the spool)."""
    status = facts.last_status
    if status is None or status.disk_free_mb is None:
        return _unknown("disk", "its free disk")
    amber, red = limits.disk_free_mb
    level = grade_falling(status.disk_free_mb, limits.disk_free_mb)
    return Grade(
        level,
        f"{status.disk_free_mb:.0f} MB",
        f"amber at {amber:g} MB or less, red at {red:g}",
        f"disk {status.disk_free_mb:.0f} MB free",
    )


def check_temperature(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """CPU temperature (a Raspberry Pi throttles from about 80 °C)."""
    status = facts.last_status
    if status is None or status.cpu_temp_c is None:
        return _unknown("CPU temp", "its temperature")
    amber, red = limits.cpu_temp_c
    level = grade_rising(status.cpu_temp_c, limits.cpu_temp_c)
    return Grade(
        level,
        f"{status.cpu_temp_c:.0f} °C",
        f"amber from {amber:g} °C, red from {red:g} °C",
        f"CPU {status.cpu_temp_c:.0f} °C",
    )


def check_agent(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """The agent version, against the one every car should run (if configured)."""
    status = facts.last_status
    if status is None or status.agent_version is None:
        return _unknown("agent", "its agent version")
    expected = limits.agent_version
    if expected is not None and status.agent_version != expected:
        return Grade(
            "amber",
            status.agent_version,
            f"expected {expected}: update over the air",
            f"agent {status.agent_version}, expected {expected}",
        )
    return Grade("green", status.agent_version, "agent version as expected")


def check_power(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Grade:
    """On UPS battery means the car was switched off (the computer uploads and shuts down)."""
    status = facts.last_status
    if status is None or status.is_ups_on_battery is None:
        return _unknown("power", "its power source")
    if status.is_ups_on_battery:
        return Grade(
            "amber", "battery", "on UPS battery: the car is switched off", "on UPS battery"
        )
    return Grade("green", "car", "powered by the car")


@dataclass(frozen=True)
class Check:
    """A named check and how to grade it; `from_report` checks read only the status report."""

    name: str
    label: str
    evaluate: Evaluate
    from_report: bool = True


CHECKS: tuple[Check, ...] = (
    Check("ping", "last ping", check_ping, from_report=False),
    Check("status", "last status", check_status, from_report=False),
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


class HeldLevel(NamedTuple):
    """A level after hysteresis, and the change waiting out its hold (if any)."""

    level: Level
    report: int  # the report whose grade is shown for `level`
    pending: Level | None = None
    pending_for_s: float = 0.0


def hold_levels(times_s: Sequence[float], levels: Sequence[Level], hold_s: float) -> HeldLevel:
    """The level a check holds after its reports (oldest first), with hysteresis.

    Later reports on one side of the held level (all better, or all worse) form a run; once a run
    spans `hold_s` seconds the level becomes the mildest level of the run (the one that held over
    all of it), so a car whose rate dips for one report keeps its level, and one that turns to
    flicker between amber and red keeps it until the flicker has lasted (then, below, it shows
    the flicker's worst). The reports after the run's mildest one then count towards the next
    change, so a check falling green -> amber -> red turns red once red has held `hold_s`, not
    a hold after the amber step was taken.

    The level to start from is the worst of the settled reports, those more than
    `HOLD_PERIODS_REPLAYED - 1` hold periods older than the newest (the first report when none
    is). Starting from the oldest report alone made the answer depend on which report the
    replayed window happened to begin with, so a check whose reports alternate flipped each time
    the window slid by one report. From the worst, a check that changes and lasts settles as
    before (its run spans the newer hold periods), one bad report is outlasted by the good ones
    after it, and reports that keep changing without any level holding show, once they have
    lasted past the newer periods, the worst of them: a car is not cleared on evidence that
    never settled.
    """
    if not levels:
        raise ValueError("hold_levels needs at least one report")
    settled_until = times_s[-1] - (HOLD_PERIODS_REPLAYED - 1) * hold_s
    settled = [i for i in range(len(levels)) if times_s[i] <= settled_until] or [0]
    held_index = max(settled, key=lambda i: (SEVERITY[levels[i]], i))
    held = levels[held_index]
    run_start: int | None = None
    run_side = 0
    mildest = 0
    index = held_index + 1
    while index < len(levels):
        step = SEVERITY[levels[index]] - SEVERITY[held]
        if step == 0:
            run_start, held_index = None, index
            index += 1
            continue
        side = 1 if step > 0 else -1
        if run_start is None or side != run_side:
            run_start, run_side, mildest = index, side, index
        elif abs(step) <= abs(SEVERITY[levels[mildest]] - SEVERITY[held]):
            mildest = index
        if times_s[index] - times_s[run_start] >= hold_s:
            held, held_index, run_start = levels[mildest], mildest, None
            # the reports after the mildest one count for the next change from its level: a
            # check falling green -> amber -> red turns red once red has held, not a hold later
            index = mildest + 1
            continue
        index += 1
    if run_start is None:
        return HeldLevel(held, held_index)
    pending_for = times_s[-1] - times_s[run_start]
    return HeldLevel(held, held_index, levels[mildest], pending_for)


class ReportAsSent(NamedTuple):
    """One status report as the car's facts stood when it was sent: what the hysteresis of a
    report-based check grades it on (`_graded`)."""

    facts: VehicleFacts
    sent_at: datetime
    ts_s: float


def _reports_as_sent(facts: VehicleFacts) -> tuple[ReportAsSent, ...]:
    """The car's reports, oldest first, each with the facts it stood for. Each report is graded
    as of when it was sent, so nothing it says has aged (graded as of its `ts`, a car whose
    clock runs ahead would have its plans aged by its lead). Built once per car and shared by
    all its report-based checks (the fleet page grades every car's reports on each view)."""
    if facts.last_status is None or not facts.earlier_statuses:
        return ()
    return tuple(
        ReportAsSent(
            # graded as of its sending, which the server's lag then has nothing to add to
            replace(facts, last_status=report, server_lag_s=0.0),
            _sent_at(report.ts, report.received_at),
            report.ts.timestamp(),
        )
        for report in (*facts.earlier_statuses, facts.last_status)
    )


def _graded(
    check: Check,
    facts: VehicleFacts,
    now: datetime,
    limits: Thresholds,
    reports: Sequence[ReportAsSent],
) -> CheckResult:
    latest = check.evaluate(facts, now, limits)
    if not check.from_report or not reports:
        return CheckResult(check.name, check.label, *latest)
    grades = [check.evaluate(report.facts, report.sent_at, limits) for report in reports]
    held = hold_levels(
        [report.ts_s for report in reports], [g.level for g in grades], limits.hold_s
    )
    level, shown = held.level, grades[held.report]
    pending = ""
    if held.pending is not None:
        pending = (
            f"{held.pending} for {held.pending_for_s:.0f} s of the {limits.hold_s:g} s "
            "it must hold to change"
        )
    # What the silence since the latest report adds (a plan ageing) is no flicker, and no later
    # report can hold it: it shows at once. Held back, a car fallen silent kept a fresh plan.
    if SEVERITY[latest.level] > max(SEVERITY[grades[-1].level], SEVERITY[level]):
        level, shown, pending = latest.level, latest, ""
    return CheckResult(
        check.name, check.label, level, latest.value, latest.detail, shown.reason, pending
    )


def assess(facts: VehicleFacts, now: datetime, limits: Thresholds) -> Readiness:
    """Grade every check (with hysteresis) and decide whether the vehicle is cleared."""
    results = []
    reports = _reports_as_sent(facts)
    for check in CHECKS:
        result = _graded(check, facts, now, limits, reports)
        if result.level == "green":
            result = replace(result, reason="")
        results.append(result)
    problems = tuple(r.reason for r in results if r.level == "red")
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


def reason_counts(readinesses: Sequence[Readiness]) -> Mapping[str, int]:
    """How many cars each check keeps from being cleared (the count above the fleet table)."""
    counts: dict[str, int] = {}
    for readiness in readinesses:
        if readiness.verdict != "not cleared":
            continue
        for check in readiness.checks:
            if check.level == "red":
                counts[check.name] = counts.get(check.name, 0) + 1
    return counts
