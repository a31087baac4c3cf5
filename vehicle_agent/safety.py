"""The independent safety layer: every frame the agent sends is re-checked here, from its bytes.

It trusts nothing upstream (controller, limiter, sequencer, frame builder): the frame is decoded
again with the make's DBC and must pass every check, or it is not sent, counted and logged:
- allowed: the make's one command message (standard id, DBC length, valid checksum), and none
  to a car that acts on no frame of the agent's (the 2023 Rogue: a GPIO board presses its
  buttons, through `admit_press`);
- the command message's other signals: what the agent's frame builder sets, and nothing else
  (`CarInterface.foreign_inputs`: on the RAV4's ACC_CONTROL a second acceleration field, the
  distance button, a malfunction shown on the dash or braking not permitted are refused);
- values: finite, acceleration within [-3, 1.5] m/s^2 and within the jerk limits of the last
  request (or of the car's measured acceleration when taking over), no cancel request, no
  request for more speed 2 mph over the fleet's top speed (73 mph, the limiter's); only the
  plus, minus and gap buttons, one at a time, a new press no sooner than 0.45 s after the last,
  no hold longer than 1.1 s (the sequencer holds 0.9 s for one 5 mph step; a button held
  1.2 s takes a second one on the fleet's cars, 2 x the 0.6 s long-press step);
- rate: no faster than 0.8 x the make's command period (but for the one release that ends a
  press: a stopping agent must not leave a press in the car's last frame);
- the car: ACC engaged by the driver, the car state valid and fresh, a press only while the
  frames it is judged from (engagement, set points, pedals: `CarInterface.press_inputs`) were
  read at most 2 of their periods ago, no press while the stock
  ACC holds a standstill for the driver (the 2023 Rogue's CRUISE_STATE 4: + resumes it), and no
  release of a standstill the stock ACC may hold for the driver to resume (the RAV4's
  RELEASE_STANDSTILL)
  but from a reading of it at most 2 of its periods old that shows none held
  (`check_standstill_release`; the port builds no other release, so this refuses only a frame
  built wrong, not every late PCM_CRUISE);
- the copy: a press whose frame copies the car's own latest frame of the command message (the
  Nissan's CRUISE_THROTTLE, pedals and brake included) only from one read at most 2 of its
  periods ago (`check_copy`), and never in a frame that shows the driver's brake or gas
  (`CarInterface.driver_inputs`; a release is).
"""

from __future__ import annotations

import logging
import math
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

import can

from contract.controllers import FLEET_TOP_SPEED_MPH
from contract.units import MPH_PER_MPS, MPS_PER_MPH
from vehicle_agent.actuators import AccelLimits
from vehicle_agent.cars import CarInterface, CarState, CruiseButton
from vehicle_agent.cars.base import Signals
from vehicle_agent.codec import Codec, FrameError
from vehicle_agent.logs import ThrottledLog

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SafetyLimits:
    """What the safety layer lets through."""

    accel: AccelLimits = field(default_factory=AccelLimits)
    # Slack on the jerk check for rounding in the frame's 0.001 m/s^2 resolution.
    jerk_tolerance_mps2: float = 0.01
    # A car state older than this is not fresh (2.5 control periods at 10 Hz).
    max_input_age_s: float = 0.25
    min_period_fraction: float = 0.8
    min_press_interval_s: float = 0.45
    # A press follows a release held at least this long (the sequencer releases for 0.25 s):
    # a 50 ms blip between two holds is no release a car reliably sees, and two 1.1 s holds
    # read as one would cross the 1.2 s of a second 5 mph step.
    min_release_s: float = 0.15
    max_hold_s: float = 1.1
    allowed_buttons: frozenset[CruiseButton] = frozenset(
        {CruiseButton.PLUS, CruiseButton.MINUS, CruiseButton.GAP}
    )
    # A previous request older than this is no reference for the jerk check (s).
    jerk_reference_s: float = 0.5
    # A car frame a command is built from counts only when it was read at most this many of its
    # periods ago (`_fresh_age_s`). The car state stays valid for 10 periods (0.5 s on the
    # Nissan), and a frame that old may no longer be the car: a copy of the Nissan's own frame
    # of the command message (`copies_command_frame`) re-sends pedal and brake values the
    # driver may have changed since. 2 periods let one frame come late or go missing.
    fresh_periods: float = 2.0
    # No acceleration frame asks for more speed while the car reads this far over the fleet's
    # top speed (`AccelLimits.top_speed_mps`). The limiter's request is already at most 0 over
    # the top and follows its bound within the jerk limits, so one still positive this far over
    # (2 mph) comes from a frame built without the limiter.
    over_top_speed_tolerance_mps: float = 2.0 * MPS_PER_MPH
    # No press of + starts while the car's ACC is set at or over the fleet's top speed, and
    # none goes on once the setting is this far over it (a held + that stepped past): the
    # paper's clip keeps a button car's setting at 73 mph, and a request that skipped it (a
    # bug upstream) must not become the car's setting.
    top_setting_mph: float = FLEET_TOP_SPEED_MPH
    over_top_setting_tolerance_mph: float = 2.0

    @property
    def more_speed_refused_over_mps(self) -> float:
        """The speed over which no acceleration frame may ask for more: the fleet's top speed
        and its tolerance (75 mph). The agent takes over no accel car faster than this, as its
        first requests, starting from the car's own acceleration, would be refused."""
        return self.accel.top_speed_mps + self.over_top_speed_tolerance_mps


@dataclass(frozen=True, slots=True)
class Refusal:
    """Why the safety layer will not let a command through: a kind, which the refusals are
    counted by, and the detail logged."""

    kind: str
    detail: str

    def __str__(self) -> str:
        return self.detail


@dataclass(frozen=True, slots=True)
class SafetyContext:
    """What the safety layer knows about the car when a frame is about to leave."""

    time_s: float
    car_state: CarState
    measured_accel_mps2: float | None = None


class SafetyLayer:
    """Checks outgoing frames of one make; remembers what it let through."""

    def __init__(
        self,
        car: CarInterface,
        codec: Codec,
        limits: SafetyLimits | None = None,
        clock: Callable[[], float] | None = None,
    ) -> None:
        """`clock`, the agent's monotonic clock, tells the car state's age at the instant a
        frame is checked: the context's time is when the agent's pass began, and a pass that
        stalled after reading the car (a slow controller, a paused process) must not act on
        it. Without one, the context's time is taken as that instant."""
        self.car = car
        self.codec = codec
        self.limits = limits or SafetyLimits()
        self._clock = clock
        self.command_id = codec.frame_id(car.command_message)
        self.command_length = codec.length(car.command_message)
        self.refused: Counter[str] = Counter()
        self.sent = 0
        self._last_sent_s: float | None = None
        self._last_accel: tuple[float, float] | None = None
        self._held: frozenset[CruiseButton] = frozenset()
        self._press_started_s: float | None = None
        self._released_s: float | None = None
        # whether the last frame let through pressed a button: what the car reads now, which
        # `idle` (a hand-back) does not change
        self._last_frame_pressed = False
        self._log = ThrottledLog(log)

    def check(self, frame: can.Message, context: SafetyContext) -> Refusal | None:
        """Why `frame` must not be sent now, or None when it may."""
        now = context.time_s
        if not self.car.accepts_button_frames:
            return Refusal(
                "id", f"the {self.car.make} {self.car.model} ({self.car.key}) takes no frames"
            )
        if frame.arbitration_id != self.command_id or frame.is_extended_id:
            return Refusal("id", f"id {frame.arbitration_id:#x} is not {self.car.command_message}")
        if len(frame.data) != self.command_length:
            return Refusal(
                "length",
                f"{len(frame.data)} bytes, {self.car.command_message} has {self.command_length}",
            )
        try:
            _, signals = self.codec.decode(frame.arbitration_id, frame.data)
        except FrameError as error:
            return Refusal("decode", f"does not decode: {error}")
        if not all(math.isfinite(float(value)) for value in signals.values()):
            return Refusal("value", "non-finite signal value")
        minimum_gap = self.limits.min_period_fraction * self.car.command_period_s
        last = self._last_sent_s
        if last is not None and now - last < minimum_gap and not self._ends_a_press(signals):
            return Refusal("rate", f"rate: sent {now - last:.3f} s after the previous frame")
        foreign = self.car.foreign_inputs(signals)
        if self.car.actuation == "accel":
            if foreign is not None:
                return Refusal("signal", f"{foreign}: not the agent's to send")
            return self._check_car(context) or self._check_accel(
                self.car.commanded_accel(signals), signals, context
            )
        if foreign is not None:
            return Refusal("button", f"{foreign}: not the agent's to send")
        pressed = self.car.pressed_buttons(signals)
        driver = self.car.driver_inputs(signals) if pressed else None
        if driver is not None:
            return Refusal("driver", f"a press in a frame showing {driver}")
        return self.check_press(pressed, context)

    def _ends_a_press(self, signals: Signals) -> bool:
        """A button frame releasing what the last frame held. It passes however soon after
        that frame: releasing is always allowed, and refused, it would leave the press standing
        in the last frame the car received (an agent stopping mid-press). Only once: the
        releases after it keep the rate."""
        return (
            self.car.actuation != "accel"
            and self._last_frame_pressed
            and self.car.foreign_inputs(signals) is None
            and not self.car.pressed_buttons(signals)
        )

    def _check_car(self, context: SafetyContext) -> Refusal | None:
        state = context.car_state
        if not state.valid or state.reading is None:
            return Refusal("car state", f"car state invalid: {state.problem}")
        age = self._age_s(state.time_s, context)
        if age > self.limits.max_input_age_s:
            return Refusal("car state", f"car state {age:.2f} s old")
        if not state.reading.acc_engaged:
            return Refusal("ACC", "ACC not engaged by the driver")
        return None

    def _age_s(self, read_s: float, context: SafetyContext) -> float:
        """How old what was read at `read_s` is at the instant a frame is checked (the
        clock's, see `__init__`)."""
        checked_at = context.time_s if self._clock is None else self._clock()
        return checked_at - read_s

    def check_copy(self, read_s: float | None, context: SafetyContext) -> Refusal | None:
        """Why a press may not be built from the car's frame of the command message read at
        `read_s` (None: never read), or None when it may. Only makes whose button frames copy
        that frame (`copies_command_frame`) are asked: the copy carries the driver's pedal and
        brake besides the buttons, and the older it is, the longer the driver has had to change
        them. Aged by the clock, as the car state is: a stalled pass copies an older frame."""
        name = self.car.command_message
        if read_s is None:
            return Refusal("copy", f"no {name} of the car's to copy")
        age = self._age_s(read_s, context)
        if age > self._fresh_age_s(name):
            return Refusal("copy", f"the car's {name} to copy is {age:.2f} s old")
        return None

    def check_standstill_release(self, context: SafetyContext) -> Refusal | None:
        """Why a frame may not release a standstill the stock ACC holds for the driver to
        resume, or None when it may: only while the car's `standstill_message`, read fresh,
        shows none held. The car state stays valid on a frame of it 10 periods old (0.33 s of
        the RAV4's PCM_CRUISE), time enough for the car to have stopped and the ACC to hold it
        since, and a release judged from that frame would drive off a hold that is the
        driver's to release. Aged by the clock, as the car state is."""
        name = self.car.standstill_message
        state = context.car_state
        read_s = None if name is None else state.received_at.get(name)
        if name is None or read_s is None or state.reading is None:
            return Refusal("standstill", "releases a standstill with no reading of it")
        age = self._age_s(read_s, context)
        if age > self._fresh_age_s(name):
            return Refusal("standstill", f"releases a standstill from a {name} {age:.2f} s old")
        if state.reading.standstill_held:
            return Refusal("standstill", "releases a standstill held for the driver to resume")
        return None

    def _check_press_inputs(self, context: SafetyContext) -> Refusal | None:
        """Why a press may not be judged from the car's frames of its `press_inputs`: one
        never read, or read over `fresh_periods` of its periods ago (aged by the clock)."""
        received_at = context.car_state.received_at
        for name in self.car.press_inputs:
            read_s = received_at.get(name)
            if read_s is None:
                return Refusal("car state", f"a press with no {name} read")
            age = self._age_s(read_s, context)
            if age > self._fresh_age_s(name):
                return Refusal("car state", f"a press judged from a {name} {age:.2f} s old")
        return None

    def _fresh_age_s(self, name: str) -> float:
        """The oldest the car's frame of `name` may be for a command to be built from it:
        `fresh_periods` of its periods."""
        return self.limits.fresh_periods * self.car.messages[name].period_s

    def _check_accel(
        self, accel: float, signals: dict[str, float], context: SafetyContext
    ) -> Refusal | None:
        limits = self.limits.accel
        if not limits.min_accel_mps2 <= accel <= limits.max_accel_mps2:
            low, high = limits.min_accel_mps2, limits.max_accel_mps2
            return Refusal("acceleration", f"acceleration {accel} m/s^2 outside [{low}, {high}]")
        if signals.get("CANCEL_REQ"):
            return Refusal("cancel", "cancel request")
        speed = context.car_state.speed_mps
        top = limits.top_speed_mps
        if accel > 0.0 and speed is not None and speed > self.limits.more_speed_refused_over_mps:
            return Refusal(
                "top speed",
                f"acceleration {accel} m/s^2 at {speed * MPH_PER_MPS:.1f} mph, over the fleet's "
                f"top speed {top * MPH_PER_MPS:.0f} mph",
            )
        if self.car.releases_standstill(signals):
            refusal = self.check_standstill_release(context)
            if refusal is not None:
                return refusal
        now = context.time_s
        last = self._last_accel
        if last is not None and now - last[0] <= self.limits.jerk_reference_s:
            reference_time, reference = last
            dt = now - reference_time
        else:
            measured = context.measured_accel_mps2
            reference = measured if measured is not None and math.isfinite(measured) else 0.0
            # Judged from inside the allowed range, as the limiter moves from it.
            reference = min(max(reference, limits.min_accel_mps2), limits.max_accel_mps2)
            dt = self.car.command_period_s
        tolerance = self.limits.jerk_tolerance_mps2
        if not (
            reference - limits.max_jerk_down_mps3 * dt - tolerance
            <= accel
            <= reference + limits.max_jerk_up_mps3 * dt + tolerance
        ):
            return Refusal("jerk", f"jerk: {reference:.3f} -> {accel:.3f} m/s^2 in {dt:.3f} s")
        return None

    def check_press(
        self, pressed: frozenset[CruiseButton], context: SafetyContext
    ) -> Refusal | None:
        """Why holding `pressed` now is not allowed (releasing always is), or None."""
        if not pressed:
            return None
        now = context.time_s
        problem = self._check_car(context) or self._check_press_inputs(context)
        if problem is not None:
            return problem
        reading = context.car_state.reading
        if reading is not None and reading.standstill_held:
            return Refusal(
                "standstill", "the stock ACC holds a standstill for the driver: no press"
            )
        if not pressed <= self.limits.allowed_buttons:
            names = ", ".join(sorted(b.value for b in pressed - self.limits.allowed_buttons))
            return Refusal("button", f"button {names} is not the agent's to press")
        if len(pressed) > 1:
            return Refusal("buttons", "buttons: more than one at once")
        started = self._press_started_s
        if not self._held:
            if started is not None and now - started < self.limits.min_press_interval_s:
                return Refusal(
                    "press", f"press rate: {now - started:.2f} s after the previous press"
                )
            released = self._released_s
            if released is not None and now - released < self.limits.min_release_s:
                return Refusal("press", f"press rate: released only {now - released:.2f} s")
        elif pressed != self._held:
            return Refusal("buttons", "buttons: switching without a release")
        elif started is not None and now - started > self.limits.max_hold_s:
            return Refusal("hold", f"hold: button held {now - started:.2f} s")
        return self._check_setting(pressed, context)

    def _check_setting(
        self, pressed: frozenset[CruiseButton], context: SafetyContext
    ) -> Refusal | None:
        """+ refused at the fleet's top setting (`SafetyLimits.top_setting_mph`); a car that
        does not report its setting is not pressed at all (`EngageInputs.set_point_reported`)."""
        reading = context.car_state.reading
        setting = None if reading is None else reading.acc_speed_setting_mph
        if CruiseButton.PLUS not in pressed or setting is None:
            return None
        top = self.limits.top_setting_mph
        limit = top if not self._held else top + self.limits.over_top_setting_tolerance_mph
        if setting >= limit:
            return Refusal(
                "setting", f"setting: + with the ACC set to {setting:g} mph (top {top:g} mph)"
            )
        return None

    def refuse(self, refusal: Refusal) -> None:
        """Count (by kind) and log a command refused before it became a frame."""
        self.refused[refusal.kind] += 1
        self._log.warning(
            refusal.kind, f"safety refused {self.car.command_message}: {refusal.detail}"
        )

    def _record_press(self, pressed: frozenset[CruiseButton], now: float) -> None:
        if pressed and not self._held:
            self._press_started_s = now
        elif self._held and not pressed:
            self._released_s = now
        self._held = pressed

    def admit(self, frame: can.Message, context: SafetyContext) -> bool:
        """Check `frame`; remember it when it may be sent, count and log it when not."""
        refusal = self.check(frame, context)
        if refusal is not None:
            self.refuse(refusal)
            return False
        now = context.time_s
        self.sent += 1
        self._last_sent_s = now
        _, signals = self.codec.decode(frame.arbitration_id, frame.data)
        if self.car.actuation == "accel":
            self._last_accel = (now, self.car.commanded_accel(signals))
        else:
            pressed = self.car.pressed_buttons(signals)
            self._last_frame_pressed = bool(pressed)
            self._record_press(pressed, now)
        return True

    def admit_press(self, pressed: frozenset[CruiseButton], context: SafetyContext) -> bool:
        """The same checks for a button board that presses without CAN frames."""
        refusal = self.check_press(pressed, context)
        if refusal is not None:
            self.refuse(refusal)
            return False
        self._record_press(pressed, context.time_s)
        return True

    def idle(self) -> None:
        """The agent stopped commanding: the next request starts from the car's own state."""
        self._last_accel = None
        self._held = frozenset()


class SafeSender:
    """The only way a frame reaches the bus: through the safety layer."""

    def __init__(self, bus: can.BusABC, safety: SafetyLayer) -> None:
        self.bus = bus
        self.safety = safety
        self.send_errors = 0

    def send(self, frame: can.Message, context: SafetyContext) -> bool:
        """Send `frame` if the safety layer admits it; True when it went out."""
        if not self.safety.admit(frame, context):
            return False
        try:
            self.bus.send(frame)
        except can.CanError as error:
            self.send_errors += 1
            log.warning("CAN send failed: %s", error)
            return False
        return True
