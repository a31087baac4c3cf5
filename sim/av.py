"""Automated vehicles in the simulator, driven by the real vehicle-agent controllers.

`AgentPolicy` builds the controller's `Observation` each step from what the car would sense
(paper Table 2: the RAV4 measures the leader's gap and relative speed; the Rogue and the XT5
only the "minicar" flag) and the plan's target at its position, calls the very controller object
the agent runs (`vehicle_agent.controllers.build_controller`), and turns its action into the
acceleration the car makes: an `accel` car makes the commanded acceleration as the agent sends it,
through the agent's own `AccelLimiter` (range and jerk limits, started afresh at each engagement
from the car's acceleration, as `vehicle_agent.agent` does on taking over); an `acc` car hands
its set points to a stock-ACC model (`StockAcc`), which decides the acceleration.

Without a fresh plan (none published yet, or the last older than a car holds one, when the
INRIX feed has stopped) the agent does not command: the car drives on its stock ACC, and the
controller starts afresh with the next plan (`vehicle_agent.engage`, "plan_fresh"). An `acc`
car's ACC keeps the settings the agent left; an `accel` car's (the RAV4 takes acceleration
requests over its engaged ACC) resumes at the speed the car had when the requests stopped, our
stand-in for the set speed the driver chose, which no recording holds.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

from sim.emulator.acc import SimulatedAccCar
from sim.platoon import AvObservation
from vehicle_agent.actuators import AccelLimiter
from vehicle_agent.controllers import (
    AccelCommand,
    AccSetPoint,
    Controller,
    Observation,
    TargetProfile,
    build_controller,
)
from vehicle_agent.stopping import braking_authority_mps2

# The cars' radar reports a leader within about 80-100 m (paper Table 2, "minicar").
RADAR_RANGE_M = 100.0
# The agent pings once per second; at 10 Hz that is every 10th step.
PING_EVERY_STEPS = 10


class PlanSource(Protocol):
    """Where an AV gets its plan and where its pings go (the server, or its simulation)."""

    def profile(self, time_s: float) -> TargetProfile | None:
        """The plan the vehicle holds at `time_s`; None while it holds none fresh."""
        ...

    def record_ping(
        self, time_s: float, x_m: float, speed_mps: float, *, engaged: bool, lead_present: bool
    ) -> None:
        """A ping from the vehicle: whether its controller was engaged, whether its radar saw
        a leader (the ping's `controller_engaged` and `lead_present`)."""
        ...


class StockAcc(Protocol):
    """A car's own ACC: set points in, the acceleration it makes out."""

    def accel_mps2(
        self,
        set_point: AccSetPoint,
        time_s: float,
        speed_mps: float,
        gap_m: float | None,
        lead_speed_mps: float | None,
    ) -> float:
        """The acceleration the stock ACC makes this step."""
        ...

    @property
    def speed_setting_mph(self) -> float | None:
        """The set speed the car shows now (what the agent reads back from CAN)."""
        ...

    @property
    def gap_setting(self) -> int | None:
        """The gap bars the car shows now."""
        ...

    def hold_accel_mps2(
        self,
        time_s: float,
        speed_mps: float,
        gap_m: float | None,
        lead_speed_mps: float | None,
    ) -> float:
        """The acceleration the ACC makes on its own settings, the agent pressing nothing."""
        ...

    def cancel(self) -> None:
        """The driver braked: the ACC disengages (it engages again at the car's speed)."""
        ...


class AgentPolicy:
    """An AV policy that runs a vehicle-agent controller behind the simulated sensors."""

    def __init__(
        self,
        controller: Controller,
        plan: PlanSource,
        *,
        senses_lead_state: bool,
        lead_state_range_m: float = RADAR_RANGE_M,
        stock_acc: StockAcc | None = None,
    ) -> None:
        if controller.actuation == "acc" and stock_acc is None:
            raise ValueError(
                f"controller {controller.name} drives an ACC: a stock-ACC model is needed"
            )
        self.controller = controller
        self.plan = plan
        self.senses_lead_state = senses_lead_state
        self.lead_state_range_m = lead_state_range_m
        self.stock_acc = stock_acc
        self.braking_authority_mps2 = braking_authority_mps2(controller.actuation)
        # The ACC that drives while the agent holds no fresh plan: the `acc` car's own, or
        # the ACC under an `accel` car's requests.
        self._acc_without_plan: StockAcc = stock_acc if stock_acc is not None else SimulatedAccCar()
        self._without_plan = False
        # Whether the agent's controller drove the last step (what the next ping reports).
        self._engaged = False
        # Times the car was left to its ACC for want of a fresh plan, and the steps it drove so.
        self.plan_hand_backs = 0
        self.steps_without_plan = 0
        self._step = 0
        # The agent's limiter between an `accel` controller and the car, and whether it holds
        # this engagement's last request (it starts from the car's acceleration when not).
        self.accel_limiter = AccelLimiter()
        self._limiting = False
        self._last_speed: tuple[float, float] | None = None
        self._measured_accel_mps2 = 0.0

    def _sense(self, observation: AvObservation) -> None:
        """Every step, whoever drives: the agent pings once a second, and reads the car's
        acceleration from its successive speeds (the step's exact change here; the car filters
        the same difference)."""
        if self._step % PING_EVERY_STEPS == 0:
            self.plan.record_ping(
                observation.time_s,
                observation.position_m,
                observation.speed_mps,
                engaged=self._engaged,
                lead_present=observation.gap_m <= RADAR_RANGE_M,
            )
        self._step += 1
        if self._last_speed is not None and observation.time_s > self._last_speed[0]:
            last_time, last_speed = self._last_speed
            self._measured_accel_mps2 = (observation.speed_mps - last_speed) / (
                observation.time_s - last_time
            )
        self._last_speed = (observation.time_s, observation.speed_mps)

    def _release(self) -> None:
        """The agent stops commanding: the controller starts afresh, and so does the limiter."""
        self.controller.reset()
        self._limiting = False
        self._engaged = False

    def driver_drives(self, observation: AvObservation) -> None:
        """Handed back: the driver's braking cancels the ACC, the controller starts afresh."""
        self._sense(observation)
        self._release()
        if self.stock_acc is not None:
            self.stock_acc.cancel()

    def accel_mps2(self, observation: AvObservation) -> float:
        """Sense, decide with the agent's controller, actuate."""
        time_s = observation.time_s
        self._sense(observation)
        profile = self.plan.profile(time_s)
        lead_present = observation.gap_m <= RADAR_RANGE_M
        if profile is None:
            return self._acc_drives(observation, lead_present)
        self._without_plan = False
        self._engaged = True
        measured = self.senses_lead_state and observation.gap_m <= self.lead_state_range_m
        rel_speed = observation.lead_speed_mps - observation.speed_mps
        if self.controller.actuation == "accel" and not self._limiting:
            self.accel_limiter.reset(self._measured_accel_mps2, time_s)
            self._limiting = True
        action = self.controller.step(
            Observation(
                time_s=time_s,
                speed_mps=observation.speed_mps,
                target_speed_mps=profile.at(observation.position_m),
                position_m=observation.position_m,
                target=profile,
                lead_present=lead_present or measured,
                lead_distance_m=observation.gap_m if measured else None,
                lead_rel_speed_mps=rel_speed if measured else None,
                acc_speed_setting_mph=self.stock_acc.speed_setting_mph if self.stock_acc else None,
                acc_gap_setting=self.stock_acc.gap_setting if self.stock_acc else None,
                commanded_accel_mps2=self.accel_limiter.reference_mps2 if self._limiting else None,
            )
        )
        if isinstance(action, AccelCommand):
            return self.accel_limiter.limit(
                time_s, action.accel_mps2, speed_mps=observation.speed_mps
            )
        assert self.stock_acc is not None  # checked at construction for acc controllers
        return self.stock_acc.accel_mps2(
            action,
            time_s,
            observation.speed_mps,
            observation.gap_m if lead_present else None,
            observation.lead_speed_mps if lead_present else None,
        )

    def _acc_drives(self, observation: AvObservation, lead_present: bool) -> float:
        """No fresh plan: the agent hands the car back to its ACC (once), which drives."""
        if not self._without_plan:
            self._without_plan = True
            self.plan_hand_backs += 1
            self._release()
            if self.stock_acc is None:
                self._acc_without_plan.cancel()  # resumes at the car's speed (module docstring)
        self.steps_without_plan += 1
        return self._acc_without_plan.hold_accel_mps2(
            observation.time_s,
            observation.speed_mps,
            observation.gap_m if lead_present else None,
            observation.lead_speed_mps if lead_present else None,
        )


def agent_policy(
    controller_name: str,
    actuation: str,
    plan: PlanSource,
    params: Mapping[str, Any] | None = None,
    *,
    stock_acc: StockAcc | None = None,
    lead_state_range_m: float = RADAR_RANGE_M,
) -> AgentPolicy:
    """A policy around a controller built exactly as the agent builds it from its config.

    An `accel` car (the RAV4) measures its leader's distance and speed out to
    `lead_state_range_m`: its controller's bound acts on them, while a policy's features read a
    leader past RADAR_RANGE_M as none, as on the car. The real RAV4 reports leaders to 252 m;
    100 m, the common range, is the default (`sim evaluate --accel-lead-range`)."""
    controller = build_controller(controller_name, actuation, params)
    return AgentPolicy(
        controller,
        plan,
        senses_lead_state=actuation == "accel",
        lead_state_range_m=lead_state_range_m,
        stock_acc=stock_acc,
    )
