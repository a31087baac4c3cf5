"""The vehicle agent: read the car, decide, act behind the safety layer, report.

One `Agent` drives one car. Everything it touches is injected (CAN bus, clock, GPS, server
client, ping spool, a button board in place of CAN button frames) so tests, the simulator and
the demo build it in-process on a virtual bus with simulated time. Three entry points, each
cheap when nothing is due:
- `tick()`: read frames -> car state -> engage logic -> controller (every control period, 10 Hz)
  -> actuation (every call: presses take 0.25 s, RAV4 requests go out at ~30 Hz) -> safety ->
  send. Call it at the make's command period (`command_period_s`).
- `record()`: a 1 Hz ping into the on-disk spool.
- `network()`: config, corridor, plan polls, status reports and the spool upload (blocking
  HTTP: run it on its own thread in a car, see `runner.run_agent`).
Bad input of any kind is logged, counted and ends in the stock ACC driving; the agent keeps going.
"""

from __future__ import annotations

import logging
import math
import sqlite3
import threading
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import can
from pydantic import BaseModel, ValidationError

from contract.controllers import (
    RL_CONTROLLERS,
    ControllerConfigError,
    RlParams,
    validate_controller,
)
from contract.corridor import MIN_SPEED_FOR_HEADING_MPS, CorridorGeometry
from contract.vehicles import Ping, VehicleConfig, VehicleStatusReport
from vehicle_agent import engage
from vehicle_agent.actuators import AccelLimiter, ButtonSequencer
from vehicle_agent.cars import CarInterface, CarReading, CarState, CruiseButton
from vehicle_agent.clock import Clock, frame_age
from vehicle_agent.codec import codec_for
from vehicle_agent.controllers import (
    AccelCommand,
    AccSetPoint,
    Action,
    Controller,
    Observation,
    build_controller,
    require_finite,
)
from vehicle_agent.controllers.policy import PolicyFileError
from vehicle_agent.gps import GpsFix, GpsSource
from vehicle_agent.plan import DEFAULT_WAVE_SPEED_MPS, LanePlan, Plan, PlanError
from vehicle_agent.policies import PolicyStore
from vehicle_agent.ports import ButtonPort, CanAccelPort, CanButtonPort, require_button_board
from vehicle_agent.probes import cpu_temp_c, disk_free_mb
from vehicle_agent.safety import SafeSender, SafetyContext, SafetyLayer
from vehicle_agent.server import (
    NewPlan,
    NotAuthorized,
    NoValidPlan,
    PlanNotServed,
    ServerClient,
    ServerError,
    ServerUnavailable,
    UnexpectedAnswer,
)
from vehicle_agent.spool import PingSpool
from vehicle_agent.state import CarStateReader
from vehicle_agent.stopping import StoppingCheck
from vehicle_agent.uplink import PingUplink

log = logging.getLogger(__name__)

AGENT_VERSION = "0.1.0"
CONTROL_PERIOD_S = 0.1
# A GPS fix older than this is no fix (s).
GPS_MAX_AGE_S = 2.0
# A control pass's snapshot older than this says nothing of the car now (s): passes renew it
# every command period, so no pass has completed since (a call stuck in the loop, every pass
# failing), and what it read and whether it commanded are history (`status_report`).
SNAPSHOT_MAX_AGE_S = 1.0
# The wall clock may differ this much from the GPS receiver's time of a fix before the agent
# stamps no ping with it (s): a receiver reports up to a second late, a Pi without a real-time
# clock boots at its last shutdown's time, hours or days off, until NTP sets it.
MAX_CLOCK_SKEW_S = 5.0
# The car's button message echoes the agent's own presses for a moment after release (s).
ECHO_GRACE_S = 0.3
# How long a fault keeps its engage check failing (s), per check. A controller that raised, the
# safety layer refusing a command, or the CAN bus refusing to send one: 1 s, so a fault that
# persists is retried after the hold and the engage wait, not at the control rate. Presses the
# car did not confirm (the sequencer gave up: a broken button wire, a car ignoring the frames):
# 10 s, as each retry costs `max_retries` futile presses.
FAULT_HOLDS_S = {
    "controller_ok": 1.0,
    "actuator_ok": 1.0,
    "commands_sent": 1.0,
    "presses_confirmed": 10.0,
}
# The reason reported when a pass of the control loop failed outright (`Agent.tick`).
STEP_FAILED = "agent step failed"
# How often the config is re-read (s), and the longest back-off after failures (s).
CONFIG_REFRESH_S = 60.0
MAX_BACKOFF_S = 30.0
# How long the first status report waits for the first config (`_first_status_may_go`): a config
# refused at start is asked again 2, 4, 8 and 16 s after each failure (at 0, 2, 6, 14 and 30 s,
# each request up to its timeout later), so its fifth try falls inside the wait.
FIRST_STATUS_WAIT_S = 45.0
# The longest the stop waits for the answer to an upload in flight (s): the request may take
# twice the HTTP timeout (its connection, then its answer), but systemd gives the whole stop 10 s
# (deploy/smoothfleet-agent.service), two loop joins (`runner.LOOP_JOIN_S`) and the network
# thread's join included. Past it the pings stay spooled and go again as duplicates.
STOP_UPLOAD_WAIT_S = 3.0
# The longest Retry-After honoured (s): a server asking for more is polled again after this.
MAX_RETRY_AFTER_S = 300.0
# Low-pass time constant of the acceleration estimated from the speed (s).
ACCEL_FILTER_S = 0.3


def fix_is_current(fix: GpsFix | None, now_s: float) -> bool:
    """Whether `fix` still says where the car is at monotonic `now_s`. A receiver gone quiet
    (unplugged, no sky, gpsd stopped) or control passes that no longer run leave the last fix in
    place; past GPS_MAX_AGE_S it neither engages the agent nor goes out as a position or as
    "GPS fix" in the piStatus report, which clears the car for deployment."""
    return fix is not None and fix.has_fix and now_s - fix.time_s <= GPS_MAX_AGE_S


# The config's fields whose change leaves how the agent drives the car as it was: the periods
# of its network and telemetry jobs; `stale_plan_after_s`, which the plan-freshness check
# reads from the config held at every control pass, so a new value takes effect there on its
# own (a shorter one that makes the plan stale hands back by that check); the route, a name
# for the people (the agent reads none: the corridor and lane are what it drives by); `active`
# and `in_maintenance`, the enabled check's, which hands back by itself with its own reason;
# and the version. Every other field (the controller, its parameters and policy, the
# actuation, the corridor, the lane, the car), and any field added later, hands the car back
# to take over anew: a field forgotten here costs a hand-back, never a controller run on a
# config it was not built for.
FIELDS_KEEPING_CONTROL = frozenset(
    {
        "ping_period_s",
        "status_period_s",
        "plan_poll_s",
        "stale_plan_after_s",
        "route",
        "active",
        "in_maintenance",
        "config_version",
    }
)


def controls_alike(before: VehicleConfig, after: VehicleConfig) -> bool:
    """Whether the controller built for `before` may go on commanding under `after`: they
    differ only in FIELDS_KEEPING_CONTROL."""
    driving = set(VehicleConfig.model_fields) - FIELDS_KEEPING_CONTROL
    return before.model_dump(include=driving) == after.model_dump(include=driving)


@dataclass(frozen=True)
class Assignment:
    """What the server's config made of this vehicle: ready-to-use objects."""

    config: VehicleConfig
    corridor: CorridorGeometry
    controller: Controller


@dataclass(frozen=True)
class Snapshot:
    """The agent at one tick, for telemetry (read by other threads)."""

    time_s: float
    wall: datetime
    reading: CarReading | None
    can_problem: str | None
    fix: GpsFix | None
    x_m: float | None
    on_corridor: bool
    mode: engage.Mode
    reason: str
    plan_id: int | None
    plan_age_s: float | None
    controller: str | None
    accel_mps2: float | None
    # The sha256 of the trained policy the assigned controller evaluates (RL controllers).
    policy_sha256: str | None = None
    # The version of the config the assignment came with: reported beside the controller and
    # policy of the same pass, so a status never pairs a new version with the old policy.
    config_version: int | None = None


# Doublings past any period's reach of MAX_BACKOFF_S (a period of 1 ms doubled 24 times is
# 4.7 h).
MAX_BACKOFF_DOUBLINGS = 25


@dataclass
class Schedule:
    """When a periodic job next runs, with exponential back-off after failures."""

    next_s: float = 0.0
    failures: int = 0
    # The period `next_s` is one of since the last success; None while the job backs off or
    # waits for the server's Retry-After, whose times are not the period's to move.
    period_s: float | None = None

    def due(self, now: float) -> bool:
        """True when it is time."""
        return now >= self.next_s

    def done(self, now: float, period_s: float) -> None:
        """It worked: next run one period from now."""
        self.failures = 0
        self.next_s = now + period_s
        self.period_s = period_s

    def failed(self, now: float, period_s: float) -> None:
        """It failed: retry after a growing delay, never longer than MAX_BACKOFF_S."""
        # counted no further than the cap needs: 2 ** 1024 overflows a float, and after 1,025
        # failures in a row (8.5 h at the cap) the job was retried on every network pass
        self.failures = min(self.failures + 1, MAX_BACKOFF_DOUBLINGS)
        self.next_s = now + min(period_s * 2 ** (self.failures - 1), MAX_BACKOFF_S)
        self.period_s = None

    def not_before(self, time_s: float) -> None:
        """The next run no sooner than `time_s` (a server's Retry-After)."""
        if time_s > self.next_s:
            self.next_s = time_s
            self.period_s = None

    def bring_forward(self, time_s: float) -> None:
        """The next run no later than `time_s`: what it does is needed now."""
        if time_s < self.next_s:
            self.next_s = time_s
            self.period_s = None

    def rebase(self, period_s: float) -> None:
        """Count the next run from the last success with `period_s`, the config's period now.
        The next run was set with the period of the config then: a status period cut from
        600 s to 5 s otherwise waited out the 600 s before the first report at 5 s, and a
        lengthened one ran once more at the old pace."""
        if self.period_s is not None and self.period_s != period_s:
            self.next_s += period_s - self.period_s
            self.period_s = period_s


@dataclass
class AgentStats:
    """Counters for status reports and tests."""

    ticks: int = 0
    control_steps: int = 0
    pings_spooled: int = 0
    pings_uploaded: int = 0
    # Pings not stamped because the wall clock disagreed with the GPS time (MAX_CLOCK_SKEW_S).
    pings_clock_unset: int = 0
    # Pings the server refused for now (`Rejection.retryable`) and the spool keeps to send again.
    pings_held_back: int = 0
    # Pings given up, though the server refused them for now, as stamped by a clock that ran
    # ahead (`uplink.STAMPED_AHEAD_GIVE_UP_S`); also in the spool's `rejected`.
    pings_stamped_ahead: int = 0
    # Fields left out of a ping or status report because they broke the contract, per message.
    fields_dropped: Counter[str] = field(default_factory=Counter)
    handbacks: Counter[str] = field(default_factory=Counter)
    server_errors: Counter[str] = field(default_factory=Counter)
    plans_refused: int = 0
    controller_errors: int = 0
    policy_downloads: int = 0
    policies_refused: int = 0
    # Assigned policies downloaded whole but not kept: the car could not write them (OSError).
    policies_not_kept: int = 0
    # Uploads stopped by the spool's own disk (full, read-only), not by the server.
    spool_errors: int = 0


class Agent:
    """One car's agent."""

    def __init__(
        self,
        *,
        vehicle_id: str,
        car: CarInterface,
        bus: can.BusABC,
        clock: Clock,
        gps: GpsSource,
        spool: PingSpool,
        server: ServerClient | None = None,
        button_port: Callable[[SafetyLayer], ButtonPort] | None = None,
        dbc_cache: Path | None = None,
        engage_policy: engage.EngagePolicy | None = None,
        wave_speed_mps: float = DEFAULT_WAVE_SPEED_MPS,
        policies: PolicyStore | None = None,
    ) -> None:
        self.vehicle_id = vehicle_id
        self.car = car
        self.bus = bus
        self.clock = clock
        self.gps = gps
        self.spool = spool
        self.server = server
        self.policies = policies
        self.engage_policy = engage_policy or engage.EngagePolicy()
        self.wave_speed_mps = wave_speed_mps
        self.codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
        self.reader = CarStateReader(car, self.codec)
        self.stopping = StoppingCheck(car.actuation)
        self.safety = SafetyLayer(car, self.codec, clock=self.clock.monotonic)
        self.sender = SafeSender(bus, self.safety)
        self.sequencer = ButtonSequencer()
        self.limiter = AccelLimiter()
        self.buttons: ButtonPort | None = None
        self.accel_port: CanAccelPort | None = None
        require_button_board(car, has_board=button_port is not None)
        if car.actuation == "acc":
            self.buttons = (
                button_port(self.safety)
                if button_port is not None
                else CanButtonPort(
                    car,
                    self.codec,
                    self.sender,
                    lambda: self.reader.latest,
                    self.reader.received_at,
                )
            )
        else:
            self.accel_port = CanAccelPort(car, self.codec, self.sender)
        self.stats = AgentStats()
        self.started_s = clock.monotonic()
        self.assignment: Assignment | None = None
        self.lane_plan: LanePlan | None = None
        self.state = engage.INITIAL
        self.snapshot: Snapshot | None = None
        self._running: Assignment | None = None
        self._next_control_s = 0.0
        self._requested_accel = 0.0
        self._own_button: CruiseButton | None = None
        self._own_released: tuple[float, CruiseButton] | None = None
        # engage check (a key of FAULT_HOLDS_S) -> until when its last fault fails it
        self._faults_until: dict[str, float] = {}
        # What the last control pass raised, while passes keep failing (None once one succeeds):
        # the status names it rather than only the time since the last good pass.
        self._step_failure: str | None = None
        # The last config could not be adopted: its controller's policy could not be had or
        # was refused, or its parameters do not build (the car's log says which).
        self._controller_unbuilt = False
        self._last_settings: tuple[float | None, int | None] | None = None
        self._accel_estimate: tuple[float, float, float] | None = None  # time, speed, accel
        self._located: tuple[GpsFix, CorridorGeometry, float, bool] | None = None
        self._config_schedule = Schedule()
        # The newest config version a plan answer announced that the refresh was brought forward
        # for (`_config_announced`).
        self._config_version_announced = 0
        self._plan_schedule = Schedule()
        self._status_schedule = Schedule()
        self._status_sent = False
        self._upload_schedule = Schedule()
        self.uplink = PingUplink(spool, clock.now)
        # When the last ping was due (its period's slot), None before the first.
        self._ping_slot_s: float | None = None
        # Held by an upload for its whole call: the stop closes the spool only once the answer
        # in flight has been settled in it (`shutdown`).
        self._upload_lock = threading.Lock()
        # Set by `shutdown`: no control pass re-engages or sends after it, and no upload starts.
        self._stopped = threading.Event()
        self._last_ping_ts: datetime | None = None
        self._clock_off = False
        self._frames_at_status = (self.started_s, 0)

    # Periods the caller needs -----------------------------------------------------------------

    @property
    def command_period_s(self) -> float:
        """How often `tick()` should run: the make's command period."""
        return self.car.command_period_s

    @property
    def config(self) -> VehicleConfig | None:
        """The server's current config for this vehicle, once read."""
        return None if self.assignment is None else self.assignment.config

    # Control ----------------------------------------------------------------------------------

    def tick(self) -> None:
        """One pass of the control loop (see the module docstring).

        Whatever fails in it (the CAN interface going down under `recv`, a bug anywhere in the
        pass) hands the car back before the error goes on to the loop that logs it: left alone,
        the agent would stay ENGAGED in its reports while commanding nothing, and a button board
        would keep holding the button it held.
        """
        try:
            self._tick()
        except Exception as error:
            self._step_failure = f"{type(error).__name__}: {error}"
            self._fail_safe(STEP_FAILED)
            raise
        self._step_failure = None

    def _tick(self) -> None:
        if self._stopped.is_set():
            return
        now = self.clock.monotonic()
        wall = self.clock.now()
        self.stats.ticks += 1
        wall_epoch_s = wall.timestamp()
        while (frame := self.bus.recv(timeout=0)) is not None:
            # dated by its receipt (vehicle_agent.clock), not by this pass
            self.reader.ingest(frame, now - frame_age(wall_epoch_s, frame.timestamp))
        car_state = self.reader.snapshot(now)
        reading = car_state.reading
        measured_accel = self._estimate_accel(reading, now)
        fix = self.gps.latest()
        gps_ok = fix_is_current(fix, now)
        assignment = self.assignment
        x_m, on_corridor = self._locate(fix, reading, now) if gps_ok else (None, False)
        lane_plan = self.lane_plan
        plan_fresh = (
            assignment is not None
            and lane_plan is not None
            and lane_plan.is_fresh(wall, assignment.config.stale_plan_after_s, now)
        )
        previous = self.state
        state = engage.step(
            previous,
            engage.EngageInputs(
                time_s=now,
                controller_built=not self._controller_unbuilt,
                enabled=self._enabled(assignment),
                assignment_current=self._running is None
                or (assignment is not None and self._running.controller is assignment.controller),
                can_ok=car_state.valid,
                acc_engaged=reading is not None and reading.acc_engaged,
                set_point_reported=self.buttons is None
                or (
                    reading is not None
                    and reading.acc_speed_setting_mph is not None
                    and reading.acc_gap_setting is not None
                ),
                gps_ok=gps_ok,
                on_corridor=on_corridor,
                in_lane=self._in_lane(fix, assignment),
                plan_fresh=plan_fresh,
                plan_reaches_car=lane_plan is not None
                and x_m is not None
                and lane_plan.reaches(
                    x_m, lane_plan.lookup_shift_m(wall, self.wave_speed_mps, now)
                ),
                controller_ok=self._fault_clear("controller_ok", now),
                actuator_ok=self._fault_clear("actuator_ok", now),
                commands_sent=self._fault_clear("commands_sent", now),
                presses_confirmed=self._fault_clear("presses_confirmed", now),
                stop_within_authority=not self.stopping.needs_hand_back(now, reading),
                within_commandable_speed=self.buttons is not None
                or self._commandable_speed(reading, measured_accel),
                driver_active=self._driver_active(reading, now, previous),
            ),
            self.engage_policy,
        )
        if self._stopped.is_set():  # read again: another thread sets it
            # The stop came while this pass read the car: it handed the car back, and a state
            # stepped on from the one before it would say (and report) the car engaged again.
            return
        self.state = state
        if previous.commanding and not self.state.commanding:
            self._hand_back(self.state.reason)
        if self.state.commanding and not previous.commanding:
            self._take_over(now, measured_accel, assignment)
        if self.state.commanding and now >= self._next_control_s:
            late = now - self._next_control_s > CONTROL_PERIOD_S
            self._next_control_s = (now if late else self._next_control_s) + CONTROL_PERIOD_S
            self._control(now, wall, reading, x_m, lane_plan)
        self._actuate(now, car_state, measured_accel)
        self.snapshot = Snapshot(
            time_s=now,
            wall=wall,
            reading=reading,
            can_problem=car_state.problem,
            fix=fix,
            x_m=x_m,
            on_corridor=on_corridor,
            mode=self.state.mode,
            reason=self.state.reason,
            plan_id=None if lane_plan is None else lane_plan.plan_id,
            plan_age_s=None if lane_plan is None else lane_plan.age_s(wall, now),
            controller=None if assignment is None else assignment.config.controller.name,
            accel_mps2=measured_accel,
            policy_sha256=None if assignment is None else assignment.controller.policy_sha256,
            config_version=None if assignment is None else assignment.config.config_version,
        )

    def _commandable_speed(self, reading: CarReading | None, accel_mps2: float | None) -> bool:
        """Whether an accel car could be taken over at its speed (`EngageInputs`): at most the
        speed the safety layer refuses more over, counting what it gains while the requests
        ease off its own acceleration."""
        if reading is None:
            return False
        limits = self.safety.limits
        gain = limits.accel.speed_gain_while_easing_off_mps(accel_mps2 or 0.0)
        return reading.speed_mps + gain <= limits.more_speed_refused_over_mps

    def _enabled(self, assignment: Assignment | None) -> bool:
        if assignment is None:
            return False
        config = assignment.config
        return config.active and not config.in_maintenance

    def _locate(
        self, fix: GpsFix | None, reading: CarReading | None, now: float
    ) -> tuple[float | None, bool]:
        assignment = self.assignment
        if assignment is None or fix is None:
            return None, False
        cached = self._located
        if cached is not None and cached[0] is fix and cached[1] is assignment.corridor:
            x_m, on_corridor = cached[2], cached[3]
        else:  # a new fix: map-match it once (the receiver reports at 1-10 Hz)
            # The heading only when GPS can tell it (`trusted_heading`, for one fix in floats).
            heading = (
                fix.heading_deg
                if fix.speed_mps is not None and fix.speed_mps >= MIN_SPEED_FOR_HEADING_MPS
                else None
            )
            x_m, _, on_corridor = assignment.corridor.locate_fix(fix.lat, fix.lon, heading)
            self._located = (fix, assignment.corridor, x_m, on_corridor)
        if reading is not None:
            x_m += reading.speed_mps * max(now - fix.time_s, 0.0)
        return x_m, on_corridor

    @staticmethod
    def _in_lane(fix: GpsFix | None, assignment: Assignment | None) -> bool:
        """GPS cannot tell lanes apart: without a lane source the driver keeps the assigned
        lane (as in the field test); with one (simulation) it must match."""
        if assignment is None or fix is None or fix.lane is None:
            return True
        return fix.lane == assignment.config.assigned_lane

    def _driver_active(
        self, reading: CarReading | None, now: float, previous: engage.EngageState
    ) -> bool:
        """Brake, gas, a cruise button the agent is not pressing, or (on acceleration-actuated
        cars, whose set points the agent never touches) a changed set point while the agent
        commands the car or is held off by the driver: the hold-off runs from the driver's last
        change, not the first (a RAV4 driver stepping the set speed down every 0.5 s had the car
        taken back 0.2 s after a change, and handed back at the next)."""
        if reading is None:
            return False
        settings = (reading.acc_speed_setting_mph, reading.acc_gap_setting)
        changed = self._last_settings is not None and settings != self._last_settings
        self._last_settings = settings
        own: set[CruiseButton] = set()
        if self._own_button is not None:
            own.add(self._own_button)
        if self._own_released is not None and now - self._own_released[0] <= ECHO_GRACE_S:
            own.add(self._own_released[1])
        return (
            reading.brake_pressed
            or reading.gas_pressed
            or bool(reading.buttons - own)
            or (
                self.car.actuation == "accel"
                and changed
                and (previous.commanding or previous.mode is engage.Mode.OVERRIDDEN)
            )
        )

    def _estimate_accel(self, reading: CarReading | None, now: float) -> float | None:
        if reading is None:
            self._accel_estimate = None
            return None
        previous = self._accel_estimate
        if previous is None or now <= previous[0]:
            accel = 0.0 if previous is None else previous[2]
        else:
            dt = now - previous[0]
            raw = (reading.speed_mps - previous[1]) / dt
            accel = previous[2] + dt / (ACCEL_FILTER_S + dt) * (raw - previous[2])
        self._accel_estimate = (now, reading.speed_mps, accel)
        return accel

    def _take_over(
        self, now: float, measured_accel: float | None, assignment: Assignment | None
    ) -> None:
        """Start commanding with `assignment`, the one this pass judged the engage checks on
        (the network thread may replace or drop `self.assignment` meanwhile)."""
        assert assignment is not None  # enabled only with an assignment
        self._running = assignment
        self._running.controller.reset()
        self.limiter.reset(measured_accel or 0.0, now)
        # until the controller's first command: what the car does now, never the last request of
        # an earlier engagement (a controller failing at its first step would leave that one)
        self._requested_accel = measured_accel or 0.0
        self.safety.idle()
        self._next_control_s = now
        log.info("agent takes over (%s)", assignment.config.controller.name)

    def _hand_back(self, reason: str) -> None:
        self._running = None
        self.sequencer.stop()
        if self.accel_port is not None:
            self.accel_port.stop()
        self.safety.idle()
        self.stats.handbacks[reason] += 1
        log.info("agent hands back to the stock ACC: %s", reason)

    def _control(
        self,
        now: float,
        wall: datetime,
        reading: CarReading | None,
        x_m: float | None,
        lane_plan: LanePlan | None,
    ) -> None:
        """Step the running controller toward `lane_plan`, the plan this pass found fresh: the
        network thread may replace or drop `self.lane_plan` meanwhile, and a plan put in after
        the check (an expired one the server answered) must not be followed unchecked."""
        running = self._running
        if running is None or reading is None or lane_plan is None or x_m is None:
            return
        profile = lane_plan.profile(wall, self.wave_speed_mps, now)
        observation = Observation(
            time_s=now,
            speed_mps=reading.speed_mps,
            target_speed_mps=profile.at(x_m),
            position_m=x_m,
            target=profile,
            lead_present=reading.lead_present,
            lead_distance_m=reading.lead_distance_m,
            lead_rel_speed_mps=reading.lead_rel_speed_mps,
            acc_speed_setting_mph=reading.acc_speed_setting_mph,
            acc_gap_setting=reading.acc_gap_setting,
            commanded_accel_mps2=self.limiter.reference_mps2,
        )
        try:
            action: Action = require_finite(running.controller.step(observation))
        except Exception as error:  # whatever a controller raises is the controller's failure
            self.stats.controller_errors += 1
            log.warning("controller %s failed: %s", running.config.controller.name, error)
            self._fault("controller_ok", now)
            return
        self.stats.control_steps += 1
        if isinstance(action, AccSetPoint):
            self.sequencer.request(action.speed_setting_mph, action.gap_setting)
        elif isinstance(action, AccelCommand):
            self._requested_accel = action.accel_mps2

    def _actuate(self, now: float, car_state: CarState, measured_accel: float | None) -> None:
        if self._stopped.is_set():  # a pass that began before the stop sends nothing after it
            return
        context = SafetyContext(now, car_state, measured_accel)
        if self.buttons is not None:
            held = None
            reading = car_state.reading
            if self.state.commanding and reading is not None and reading.standstill_held:
                # The stock ACC holds the car stopped for the driver: + would resume it (drive
                # off with nobody resuming) and - may too, so nothing is pressed while it lasts.
                self.sequencer.pause()
            elif self.state.commanding and reading is not None:
                held = self.sequencer.step(
                    now, reading.acc_speed_setting_mph, reading.acc_gap_setting
                )
                if self.sequencer.stalled:
                    self._fault("presses_confirmed", now)
            if self._own_button is not None and held != self._own_button:
                self._own_released = (now, self._own_button)
            self._own_button = held
            refused_before = sum(self.safety.refused.values())
            send_errors_before = self.sender.send_errors
            self.buttons.hold(held, context)
            if sum(self.safety.refused.values()) > refused_before:
                self._fault("actuator_ok", now)
            if self.sender.send_errors > send_errors_before:
                self._fault("commands_sent", now)
        elif self.accel_port is not None and self.state.commanding and self.accel_port.due(now):
            # While the car stands until the driver resumes, the request goes to the car's 0
            # (within the jerk limits), so resuming pulls away from 0, not with what had built up.
            reading = car_state.reading
            # commanding needs a valid car state (the engage rule's can_ok), which has a reading
            assert reading is not None
            request = 0.0 if reading.standstill_held else self._requested_accel
            accel = self.limiter.limit(now, request, speed_mps=reading.speed_mps)
            send_errors_before = self.sender.send_errors
            if not self.accel_port.request(accel, context):
                sent_error = self.sender.send_errors > send_errors_before
                self._fault("commands_sent" if sent_error else "actuator_ok", now)

    # Telemetry --------------------------------------------------------------------------------

    def record(self) -> bool:
        """Spool a ping when one is due; True when one was written."""
        now = self.clock.monotonic()
        period = self.config.ping_period_s if self.config else 1.0
        # Due one period of the config now after the last ping's slot, so a new period applies
        # from that slot (a period cut from 60 s to 1 s no longer waits out the 60 s).
        slot = self._ping_slot_s
        due = -math.inf if slot is None else slot + period
        if now < due:
            return False
        late = now - due > period  # first ping, or the caller stalled
        self._ping_slot_s = now if late else due
        ping = self.ping()
        if ping is None:
            return False
        self.spool.add(ping)
        self.stats.pings_spooled += 1
        return True

    def ping(self) -> dict[str, Any] | None:
        """The ping for the latest snapshot as `contract.vehicles.Ping` JSON (None without a
        current GPS fix: lat/lon are required, and an old fix is not where the car is; None
        too when neither the car nor the receiver tells the speed, also required: 0 m/s in
        its place would show the server a car standing on the road)."""
        snapshot = self.snapshot
        fix = snapshot.fix if snapshot else None
        if snapshot is None or fix is None or not fix_is_current(fix, self.clock.monotonic()):
            return None
        reading = snapshot.reading
        speed_mps = reading.speed_mps if reading is not None else fix.speed_mps
        if speed_mps is None:
            return None
        ts = self.clock.now()
        if not self._clock_agrees_with_gps(fix, ts):
            self.stats.pings_clock_unset += 1
            return None
        if self._last_ping_ts is not None and ts <= self._last_ping_ts:
            if ts == self._last_ping_ts:
                return None  # (vehicle_id, ts) is the ping's key: never two at one instant
            # the wall clock stepped back (NTP): pings go on under the corrected times, rather
            # than none until the clock passes the last one again
            log.warning("wall clock stepped back %.1f s", (self._last_ping_ts - ts).total_seconds())
        self._last_ping_ts = ts
        ping: dict[str, Any] = {
            "vehicle_id": self.vehicle_id,
            "ts": ts.isoformat(timespec="milliseconds"),
            "lat": round(fix.lat, 7),
            "lon": round(fix.lon, 7),
            "speed_mps": round(speed_mps, 3),
            "controller_engaged": snapshot.mode is engage.Mode.ENGAGED,
        }
        optional = {
            "accel_mps2": snapshot.accel_mps2,
            "heading_deg": fix.heading_deg,
            "lane": fix.lane,
            "controller": snapshot.controller,
            "plan_id": snapshot.plan_id,
            "policy_sha256": snapshot.policy_sha256,
            "config_version": snapshot.config_version,
        }
        if reading is not None:
            optional |= {
                "acc_engaged": reading.acc_engaged,
                "acc_speed_setting_mph": reading.acc_speed_setting_mph,
                "acc_gap_setting": reading.acc_gap_setting,
                "lead_present": reading.lead_present,
                "lead_distance_m": reading.lead_distance_m,
                "lead_rel_speed_mps": reading.lead_rel_speed_mps,
            }
        for key, value in optional.items():
            if value is None or (isinstance(value, float) and not math.isfinite(value)):
                continue
            ping[key] = round(value, 3) if isinstance(value, float) else value
        if "heading_deg" in ping:
            ping["heading_deg"] = ping["heading_deg"] % 360.0
        return self._message(Ping, ping, "ping")

    def _clock_agrees_with_gps(self, fix: GpsFix, ts: datetime) -> bool:
        """Whether the wall clock, read when `fix` arrived, is within MAX_CLOCK_SKEW_S of the
        receiver's time of it (True with no receiver time). A ping stamped by a clock not yet
        set would be stored at another moment of the drive, inside the server's window."""
        if fix.utc is None:
            return True
        arrived = ts - timedelta(seconds=self.clock.monotonic() - fix.time_s)
        skew_s = (arrived - fix.utc).total_seconds()
        agrees = abs(skew_s) <= MAX_CLOCK_SKEW_S
        if agrees == self._clock_off:  # log the change, not every second
            self._clock_off = not agrees
            if agrees:
                log.warning("wall clock agrees with the GPS time again: pings resume")
            else:
                log.warning("wall clock %+.0f s off the GPS time: no pings until it is set", skew_s)
        return agrees

    def status_report(self) -> dict[str, Any]:
        """The piStatus report for now, as `contract.vehicles.VehicleStatusReport` JSON. The
        car's state and whether the controller drives it come from a snapshot of the last
        SNAPSHOT_MAX_AGE_S only: an older one is no pass running, whatever it said."""
        now = self.clock.monotonic()
        snapshot = self.snapshot
        since, frames_then = self._frames_at_status
        frames = self.reader.stats.frames
        rate = (frames - frames_then) / (now - since) if now > since else 0.0
        self._frames_at_status = (now, frames)
        fix = snapshot.fix if snapshot and fix_is_current(snapshot.fix, now) else None
        current = (
            snapshot
            if snapshot is not None and now - snapshot.time_s <= SNAPSHOT_MAX_AGE_S
            else None
        )
        reading = current.reading if current else None
        if current is not None:
            reason: str | None = current.reason
        elif snapshot is not None:
            reason = f"no control pass for {now - snapshot.time_s:.0f} s"
            if self._step_failure is not None:
                reason += f": every pass fails ({self._step_failure})"
        else:
            reason = None
        report: dict[str, Any] = {
            "ts": self.clock.now().isoformat(timespec="milliseconds"),
            "agent_version": AGENT_VERSION,
            "uptime_s": round(now - self.started_s, 1),
            "can_ok": current is not None and current.can_problem is None,
            "can_msgs_per_s": round(rate, 1),
            "gps_fix": fix is not None,
            "gps_satellites": fix.satellites if fix else None,
            "acc_available": reading.acc_available if reading else None,
            "controller": snapshot.controller if snapshot else None,
            "controller_running": current is not None and current.mode is engage.Mode.ENGAGED,
            "plan_id": snapshot.plan_id if snapshot else None,
            # aged since the pass that judged it
            "plan_age_s": round(max(snapshot.plan_age_s + now - snapshot.time_s, 0.0), 1)
            if snapshot and snapshot.plan_age_s is not None
            else None,
            "spool_backlog": self.spool.backlog(),
            "spool_dropped": self.spool.counter("dropped"),
            "disk_free_mb": disk_free_mb(self.spool.path.parent),
            "cpu_temp_c": cpu_temp_c(),
            "server_rtt_ms": round(self.server.last_rtt_ms, 1)
            if self.server and self.server.last_rtt_ms is not None
            else None,
            "config_version": snapshot.config_version if snapshot else None,
            "policy_sha256": snapshot.policy_sha256 if snapshot else None,
            "engage_reason": reason,
        }
        status = self._message(
            VehicleStatusReport,
            {key: value for key, value in report.items() if value is not None},
            "status",
        )
        assert status is not None, "a status report needs only its ts, which is always valid"
        return status

    def _message(
        self, model: type[BaseModel], fields: dict[str, Any], what: str
    ) -> dict[str, Any] | None:
        """`fields` checked against the contract model, as the JSON the server will accept.

        An optional field outside the contract (a glitching sensor: a lead 1.5 km away) is left
        out and counted rather than costing the whole message; None when a required one is bad.
        """
        for _ in range(len(fields) + 1):
            try:
                return model.model_validate(fields).model_dump(mode="json", exclude_none=True)
            except ValidationError as error:
                bad = {str(detail["loc"][0]) for detail in error.errors() if detail["loc"]}
                required = {name for name, info in model.model_fields.items() if info.is_required()}
                self.stats.fields_dropped[what] += len(bad)
                if bad & required or not bad & set(fields):
                    log.warning("%s not sent: %s", what, error.errors()[0]["msg"])
                    return None
                log.warning("%s: left out %s (outside the contract)", what, ", ".join(sorted(bad)))
                fields = {key: value for key, value in fields.items() if key not in bad}
        return None

    # Network ----------------------------------------------------------------------------------

    def network(self) -> None:
        """Config, plan, status and uploads, each when due (blocking HTTP)."""
        if self.server is None:
            return
        now = self.clock.monotonic()
        if self._config_schedule.due(now):
            self._refresh_config(now)
        config = self.config
        if config is not None:
            self._plan_schedule.rebase(config.plan_poll_s)
        if config is not None and self._plan_schedule.due(now):
            self._poll_plan(now, config)
        status_period = config.status_period_s if config else 10.0
        self._status_schedule.rebase(status_period)
        if self._status_schedule.due(now) and self._first_status_may_go(now):
            try:
                self.server.post_status(self.status_report())
                self._status_sent = True
                self._status_schedule.done(now, status_period)
            except ServerError as error:
                self._server_failed("status", error)
                self._status_schedule.failed(now, status_period)
        if self._upload_schedule.due(now):
            self.upload(now)

    def _first_status_may_go(self, now: float) -> bool:
        """The first status report waits for the car's first config and a control pass with
        it, for at most FIRST_STATUS_WAIT_S after start. Sent before, it told the server the
        agent ran no controller ("agent not enabled for this vehicle"), which the fleet page
        then held red for a whole hold period: at a demo's start half the fleet read "not
        cleared" while every car drove. A car that gets no config in that time says so."""
        if self._status_sent or now - self.started_s >= FIRST_STATUS_WAIT_S:
            return True
        snapshot = self.snapshot
        config = self.config
        return (
            config is not None
            and snapshot is not None
            and snapshot.config_version == config.config_version
        )

    def _config_announced(self, announced: int | None, running: int | None) -> bool:
        """Whether a plan answer's config version calls for reading the config now: newer than
        the one the car runs, and newer than any announced before. Once per version: a refresh
        that then fails backs off as any other (a corridor the server cannot serve yet was read
        again at every plan poll), and a replica answering from memory during a database outage
        may name an older version than the car's, which is no news."""
        if announced is None or announced <= max(running or 0, self._config_version_announced):
            return False
        self._config_version_announced = announced
        return True

    def _server_failed(self, what: str, error: ServerError) -> None:
        self.stats.server_errors[what] += 1
        # A token the server refuses needs a person; the other failures pass by themselves.
        log.log(logging.ERROR if isinstance(error, NotAuthorized) else logging.WARNING, "%s", error)

    def _refresh_config(self, now: float) -> None:
        assert self.server is not None
        try:
            config = self.server.config()
        except ServerError as error:
            self._server_failed("config", error)
            self._config_schedule.failed(now, 2.0)
            return
        current = self.assignment
        if current is not None and current.config == config:
            self._config_schedule.done(now, CONFIG_REFRESH_S)
            return
        try:
            corridor = (
                current.corridor
                if current is not None and current.config.corridor_id == config.corridor_id
                else self.server.corridor(config.corridor_id)
            )
        except ServerError as error:
            # the server's trouble, not the config's: keep what runs, ask again soon
            self._server_failed("corridor", error)
            self._config_schedule.failed(now, 2.0)
            return
        # The schedule is settled after the config is adopted, not before: a policy that fails
        # again and again then backs off (2 s doubling to MAX_BACKOFF_S) instead of counting
        # each time as a first failure and downloading every 2 s.
        try:
            self.configure(config, corridor)
        except ServerError as error:
            # the assigned policy could not be downloaded: no good policy, no controller
            self._server_failed("policy", error)
            self._controller_unbuilt = True  # first: the control pass reads the two apart
            self.assignment = None
            self._config_schedule.failed(now, 2.0)
            return
        except PolicyFileError as error:
            # a download (or kept file) that is not the policy assigned: never run, retried
            log.error("vehicle %s: policy refused: %s", self.vehicle_id, error)
            self.stats.policies_refused += 1
            self._controller_unbuilt = True  # first: the control pass reads the two apart
            self.assignment = None
            self._config_schedule.failed(now, 2.0)
            return
        except OSError as error:
            # a good download the car could not keep (a full or read-only SD card): the
            # assigned policy cannot run, and the one before it is no longer assigned
            log.error("vehicle %s: policy not kept on disk: %s", self.vehicle_id, error)
            self.stats.policies_not_kept += 1
            self._controller_unbuilt = True  # first: the control pass reads the two apart
            self.assignment = None
            self._config_schedule.failed(now, 2.0)
            return
        except (ControllerConfigError, ValueError) as error:
            log.error("vehicle %s: config not usable: %s", self.vehicle_id, error)
            self.stats.server_errors["config"] += 1
            self._controller_unbuilt = True  # first: the control pass reads the two apart
            self.assignment = None
            self._config_schedule.done(now, CONFIG_REFRESH_S)
            return
        self._controller_unbuilt = False
        self._config_schedule.done(now, CONFIG_REFRESH_S)

    def configure(self, config: VehicleConfig, corridor: CorridorGeometry) -> None:
        """Adopt a config (building its controller, unless the one held controls alike:
        `controls_alike`); raises ValueError when it cannot apply to this car (PolicyFileError:
        the policy it names is not good) and ServerError when the policy it names could not be
        downloaded. A new lane or corridor drops the plan held for the old one.
        """
        if config.actuation != self.car.actuation:
            raise ValueError(
                f"config says actuation {config.actuation}, the car ({self.car.key}) is "
                f"{self.car.actuation}"
            )
        if corridor.corridor_id != config.corridor_id:
            raise ValueError(
                f"geometry of {corridor.corridor_id}, config says {config.corridor_id}"
            )
        previous = self.assignment
        if previous is not None and controls_alike(previous.config, config):
            # the controller running goes on (the engage check compares controllers): a new
            # status period is no reason to hand the car back
            self.assignment = Assignment(config, corridor, previous.controller)
            return
        controller = build_controller(
            config.controller.name, config.actuation, self._controller_params(config)
        )
        self.assignment = Assignment(config, corridor, controller)
        if (
            previous is None
            or previous.config.assigned_lane != config.assigned_lane
            or previous.config.corridor_id != config.corridor_id
        ):
            # another lane's or corridor's targets at this car's positions are no plan for it
            self.lane_plan = None
            self._plan_schedule = Schedule()

    def _controller_params(self, config: VehicleConfig) -> dict[str, Any]:
        """The config's controller params; for a policy named only by sha256, with the file of
        the policy store that holds it (downloaded once over the API, verified before kept).

        Without a store or a server the params go as they are: the controller then runs the
        bundled policy only if it is the one named, and refuses otherwise."""
        params = dict(config.controller.params)
        if config.controller.name not in RL_CONTROLLERS or self.policies is None:
            return params
        model = validate_controller(config.controller.name, config.actuation, params)
        assert isinstance(model, RlParams)
        if model.policy_sha256 is None or model.policy is not None or self.server is None:
            return params
        server = self.server

        def download(sha256: str) -> bytes:
            self.stats.policy_downloads += 1
            return server.policy(sha256)

        actuation = RL_CONTROLLERS[config.controller.name]
        path = self.policies.fetch(model.policy_sha256, actuation, download)
        return {**params, "policy": str(path)}

    def accept_plan(
        self, plan: Plan, etag: str | None = None, served_at: datetime | None = None
    ) -> bool:
        """Hold `plan` for the assigned lane; False (and no plan held) when it has no such lane
        or is another corridor's (an answer for the assignment before a reassignment).
        `served_at`, the server's clock when it sent the plan, dates its age on arrival."""
        config = self.config
        if config is None:
            return False
        try:
            if plan.corridor != config.corridor_id:
                raise PlanError(
                    f"plan {plan.plan_id} is of corridor {plan.corridor}, the car is assigned "
                    f"{config.corridor_id}: not followed"
                )
            self.lane_plan = LanePlan(
                plan, config.assigned_lane, etag, self.clock.monotonic(), served_at
            )
        except PlanError as error:
            self.stats.plans_refused += 1
            log.warning("%s", error)
            self.lane_plan = None
            return False
        return True

    def _poll_plan(self, now: float, config: VehicleConfig) -> None:
        """Poll the plan. Whatever the network does, the held plan is kept and followed until
        its own valid_until (or stale_plan_after_s of age); only the server's explicit "no valid
        plan" ends it sooner (vehicle_agent/server.py lists every outcome). An answer naming
        another config version than the one held brings the config refresh forward."""
        assert self.server is not None
        held = self.lane_plan
        try:
            fetched = self.server.plan(config.assigned_lane, held.etag if held else None)
        except ServerError as error:
            self._server_failed("plan", error)
            if isinstance(error, UnexpectedAnswer) and error.status == 200:
                self.stats.plans_refused += 1  # a plan the agent will not follow
            self._plan_schedule.failed(now, config.plan_poll_s)
            if isinstance(error, ServerUnavailable) and error.retry_after_s:
                self._retry_after(now, error.retry_after_s)
            if isinstance(error, PlanNotServed) and self._config_announced(
                error.config_version, config.config_version
            ):
                # moved to a corridor without this lane: the new config says where to drive
                self._config_schedule.bring_forward(now)
            return
        self._plan_schedule.done(now, config.plan_poll_s)
        if self._config_announced(fetched.config_version, config.config_version):
            # The server holds a newer config for the car (an operator pulled or reassigned
            # it): read it on the next network pass, not at the refresh up to 60 s away.
            self._config_schedule.bring_forward(now)
        if isinstance(fetched, NoValidPlan):
            self.lane_plan = None
            if fetched.retry_after_s:
                self._retry_after(now, fetched.retry_after_s)
        elif isinstance(fetched, NewPlan):
            self.accept_plan(fetched.plan, fetched.etag, fetched.served_at)

    def _retry_after(self, now: float, retry_after_s: float) -> None:
        """The next plan poll no sooner than the server asked (bounded by MAX_RETRY_AFTER_S)."""
        self._plan_schedule.not_before(now + min(retry_after_s, MAX_RETRY_AFTER_S))

    def upload(self, now: float | None = None) -> int:
        """Send spooled pings (`vehicle_agent.uplink`); returns how many left the spool,
        answered for or given up. The next upload is a second away, or backs off when the
        server stopped this one."""
        if self.server is None:
            return 0
        now = self.clock.monotonic() if now is None else now
        try:
            with self._upload_lock:
                if self._stopped.is_set():
                    return 0  # the spool is closing or closed
                outcome = self.uplink.upload(self.server, self._stopped.is_set)
        except (sqlite3.Error, OSError) as spool_error:
            # the spool's disk (full, read-only): what the server took stays spooled and is
            # resent as duplicates later, but not on every network pass (it was: the same
            # batch of up to 1,000 pings five times a second)
            self.stats.spool_errors += 1
            log.warning("ping spool: %s; uploads back off", spool_error)
            self._upload_schedule.failed(now, 1.0)
            return 0
        for error in outcome.errors:
            self._server_failed("pings", error)
        self.stats.pings_uploaded += outcome.uploaded
        self.stats.pings_held_back += outcome.held_back
        self.stats.pings_stamped_ahead += outcome.stamped_ahead
        if outcome.completed:
            self._upload_schedule.done(now, 1.0)
        else:
            self._upload_schedule.failed(now, 1.0)
        return outcome.uploaded + outcome.given_up

    def _fault(self, check: str, now: float) -> None:
        """A fault: the engage check `check` fails from now for its hold (FAULT_HOLDS_S)."""
        self._faults_until[check] = now + FAULT_HOLDS_S[check]

    def _fault_clear(self, check: str, now: float) -> bool:
        """True when no fault holds `check` failing at `now`."""
        return now >= self._faults_until.get(check, -math.inf)

    def _fail_safe(self, reason: str) -> None:
        """Hand back and release any held button, trusting nothing of the failed pass."""
        now = self.clock.monotonic()
        if self.state.commanding:
            self._hand_back(reason)
        self.state = engage.failed(self.state, now, reason)
        if self.snapshot is not None:
            # telemetry reads the snapshot, which the failed pass did not renew: it must not go
            # on reporting the car as commanded
            self.snapshot = replace(self.snapshot, mode=self.state.mode, reason=reason)
        if self.buttons is None or self._own_button is None:
            return
        self._own_released = (now, self._own_button)
        self._own_button = None
        try:
            self.buttons.hold(None, SafetyContext(now, self.reader.snapshot(now)))
        except Exception:
            log.exception("releasing the %s button failed", self._own_released[1].name)

    def shutdown(self) -> None:
        """Stop commanding (the stock ACC keeps driving), let go of any held button and close
        the spool once the upload in flight, if any, has its answer (`_settle_uploads`).

        Once stopped, a control pass still running (its thread outwaited by the stop: a call
        blocked past `runner.LOOP_JOIN_S`) neither re-engages nor sends: it would have stepped
        the engage state on from the state it read before the stop and commanded the car the
        stop had just handed back."""
        self._stopped.set()
        now = self.clock.monotonic()
        if self.state.commanding:
            self._hand_back("agent stopping")
        self.state = engage.EngageState(engage.Mode.STOCK, now, None, "stopped")
        if self.buttons is not None:
            # every line, whatever the control thread (which may not have stopped) last held
            try:
                self.buttons.close(SafetyContext(now, self.reader.snapshot(now)))
            except Exception:
                log.exception("letting go of the buttons failed")
        settled = self._settle_uploads()
        try:
            self.spool.close()
        finally:
            if settled:
                self._upload_lock.release()

    def _settle_uploads(self) -> bool:
        """Stop uploads and wait for the answer to the one in flight; True when none is left
        in flight (the caller then holds `_upload_lock`).

        `run_agent` calls the stop once the network thread has had its time to end, which an
        upload over a slow uplink can outlast. The spool used to close under it: the server
        took the pings, the spool could not forget them, and the next start sent them all
        again. The wait is bounded by what the request may still take: its connection and its
        answer, each within the client's timeout (`vehicle_agent.server`). Past it the pings'
        fate is unknown; they stay spooled and go again, which the server counts as duplicates.
        """
        wait_s = (
            min(2 * self.server.timeout_s, STOP_UPLOAD_WAIT_S) if self.server is not None else 0.0
        )
        if self._upload_lock.acquire(timeout=wait_s):
            return True
        log.warning(
            "a ping upload still awaited the server's answer at the stop: its pings stay "
            "spooled and go again at the next start (the server counts those it took as "
            "duplicates)"
        )
        return False
