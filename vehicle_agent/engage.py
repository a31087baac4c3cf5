"""When the agent may command the car: a pure state machine where handing back wins.

Three modes: STOCK (the car's own ACC drives; the agent only watches), ENGAGED (the agent sends
set points or acceleration requests), OVERRIDDEN (the driver touched the brake, the gas or a cruise
button: the agent keeps off until `override_holdoff_s` after the driver's last touch).

Every step the inputs are checked in a fixed order; the first that fails hands the car back in
that same step (so within one control period): configured and enabled, CAN healthy, ACC engaged
by the driver, its set speed and gap reported (button cars), GPS healthy, on the assigned
corridor, in the assigned lane, plan fresh, controller working, actuator healthy, commands
reaching the bus, button presses confirmed by the car, and the stop the leader ahead needs
within the braking the agent may command. Taking over needs all of them to have held for
`engage_after_s` without interruption, so a flickering input cannot
toggle control on and off at the loop rate, and, for that whole wait, the car slow enough for
the agent to command (`within_commandable_speed`). That one only bars taking over: a car
the agent commands that goes faster stays commanded.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass


class Mode(enum.Enum):
    """Who drives."""

    STOCK = "stock"
    ENGAGED = "engaged"
    OVERRIDDEN = "overridden"


@dataclass(frozen=True, slots=True)
class EngageInputs:
    """Everything the decision depends on, sampled at one instant."""

    time_s: float
    # The assigned controller could be built: its policy downloaded, verified and kept, its
    # parameters valid. Without it the car has no controller, and the reason says so rather
    # than "not enabled", which is an operator's choice.
    controller_built: bool
    # Active and not in maintenance: the operator's choice.
    enabled: bool
    # The controller running is the one of the assignment held: a new config that changes how
    # the car is driven (its controller, parameters, policy, actuation, corridor, lane; not a
    # period: `agent.FIELDS_KEEPING_CONTROL`) hands the car back, and the agent takes over anew
    # with the new controller. Reported as its own reason: it was "not enabled", the operator's
    # choice, which it is not.
    assignment_current: bool
    can_ok: bool
    acc_engaged: bool
    # The car reports the ACC set speed and gap a button car's presses step from (always true
    # where the agent requests accelerations): without them the sequencer cannot press.
    set_point_reported: bool
    gps_ok: bool
    on_corridor: bool
    in_lane: bool
    plan_fresh: bool
    # The plan's lane covers the car's position (`LanePlan.reaches`).
    plan_reaches_car: bool
    # The controller gave a command at its last steps (it raised none within the hold).
    controller_ok: bool
    actuator_ok: bool
    # The command frames went out: the CAN bus took the last ones (within the hold).
    commands_sent: bool
    # The car confirmed the agent's button presses (no stall of the sequencer within the hold).
    presses_confirmed: bool
    # The stop the radar's leader needs is within the braking the agent may command
    # (vehicle_agent.stopping).
    stop_within_authority: bool
    # The agent could command the car from its speed: an accel car at most 2 mph over the
    # fleet's top speed once it has gained what it will while its requests ease off its own
    # acceleration (`SafetyLimits.more_speed_refused_over_mps`,
    # `AccelLimits.speed_gain_while_easing_off_mps`; always true for a button car, whose own
    # ACC slows it to any setting). Faster, the safety layer refuses the first requests, which
    # start from the car's own acceleration, and the car would be handed back at once. It bars
    # only taking over: a commanded car that goes over the top (downhill) is slowed back by the
    # limiter, whose requests there are at most 0, so it is not in CHECKS.
    within_commandable_speed: bool
    driver_active: bool


# The checks in order, with the reason reported when one fails.
CHECKS: tuple[tuple[str, str], ...] = (
    ("controller_built", "the assigned controller cannot run (its policy or parameters)"),
    ("enabled", "agent not enabled for this vehicle"),
    ("assignment_current", "a new assignment: taking over anew"),
    ("can_ok", "CAN inputs not healthy"),
    ("acc_engaged", "ACC not engaged by the driver"),
    ("set_point_reported", "ACC set speed or gap not reported by the car"),
    ("gps_ok", "no GPS fix"),
    ("on_corridor", "off the assigned corridor"),
    ("in_lane", "not in the assigned lane"),
    ("plan_fresh", "no fresh plan"),
    ("plan_reaches_car", "the plan does not reach the car's position"),
    ("controller_ok", "controller failed"),
    ("actuator_ok", "actuator refused by the safety layer"),
    ("commands_sent", "commands not reaching the CAN bus"),
    ("presses_confirmed", "button presses not confirmed by the car"),
    ("stop_within_authority", "stopping needs more braking than the agent may command"),
)
# The reason reported while every check passes but the car is too fast to take over.
TOO_FAST = "above the fleet's top speed"


@dataclass(frozen=True, slots=True)
class EngagePolicy:
    """Timings of the state machine (s)."""

    engage_after_s: float = 1.0
    override_holdoff_s: float = 3.0


@dataclass(frozen=True, slots=True)
class EngageState:
    """The mode, since when, since when every check has passed, and why (not) engaged."""

    mode: Mode
    since_s: float
    ready_since_s: float | None
    reason: str

    @property
    def commanding(self) -> bool:
        """True when the agent commands the car."""
        return self.mode is Mode.ENGAGED


INITIAL = EngageState(Mode.STOCK, 0.0, None, "starting")


def first_failure(inputs: EngageInputs) -> str | None:
    """The reason of the first failing check, or None when all pass."""
    for name, reason in CHECKS:
        if not getattr(inputs, name):
            return reason
    return None


def failed(state: EngageState, now: float, reason: str) -> EngageState:
    """The state after a pass of the control loop failed outright: not engaged, every check to
    hold anew for `engage_after_s`. An override keeps its mode and the time of the driver's
    last touch, so a failure never cuts short the hold-off the driver is owed."""
    if state.mode is Mode.OVERRIDDEN:
        return EngageState(Mode.OVERRIDDEN, state.since_s, None, reason)
    return EngageState(Mode.STOCK, now, None, reason)


def step(state: EngageState, inputs: EngageInputs, policy: EngagePolicy) -> EngageState:
    """The next state; never ENGAGED while a check fails or the driver is active, nor taking
    over a car too fast to command."""
    now = inputs.time_s
    if inputs.driver_active:
        return EngageState(Mode.OVERRIDDEN, now, None, "driver override")
    if state.mode is Mode.OVERRIDDEN and now - state.since_s < policy.override_holdoff_s:
        return state
    failure = first_failure(inputs)
    if failure is None and state.mode is not Mode.ENGAGED and not inputs.within_commandable_speed:
        failure = TOO_FAST
    if failure is not None:
        if state.mode is Mode.STOCK and state.reason == failure:
            return state
        return EngageState(Mode.STOCK, now, None, failure)
    if state.mode is Mode.ENGAGED:
        return state
    ready_since = state.ready_since_s if state.ready_since_s is not None else now
    if now - ready_since >= policy.engage_after_s:
        return EngageState(Mode.ENGAGED, now, ready_since, "engaged")
    return EngageState(
        Mode.STOCK,
        state.since_s if state.mode is Mode.STOCK else now,
        ready_since,
        "waiting for steady conditions",
    )
