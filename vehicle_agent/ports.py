"""Where commands leave the agent: the make's command frames on CAN, or a GPIO button board.
Everything goes through the safety layer first; releasing a button is always allowed.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Protocol

import can

from vehicle_agent.cars import CarInterface, CruiseButton
from vehicle_agent.cars.base import Signals
from vehicle_agent.codec import Codec
from vehicle_agent.safety import Refusal, SafeSender, SafetyContext, SafetyLayer

log = logging.getLogger(__name__)

# After a press, keep sending this many released frames so the car sees the release even if a
# frame is lost.
RELEASE_FRAMES = 3
# Send when the period is this nearly over (a tick of the loop may land a little early).
PERIOD_SLACK = 0.9


class ButtonBoardRequired(ValueError):
    """The car takes no button frames on CAN (`CarInterface.accepts_button_frames`) and no
    button board was given: the message names the setting."""


def require_button_board(car: CarInterface, *, has_board: bool) -> None:
    """Refuse a car the agent could press no button on: an ACC car that ignores injected
    button frames (the 2023 Rogue) with no board wired to its switches would follow no plan.
    The CLI asks before it opens the bus; the agent asks again for every other caller."""
    if car.actuation == "acc" and not has_board and not car.accepts_button_frames:
        raise ButtonBoardRequired(
            f"the {car.make} {car.model} ({car.key}) takes no button frames on "
            "CAN: its buttons are pressed through a GPIO button board, so set "
            "SMOOTHFLEET_AGENT_BUTTON_BOARD (e.g. plus=17,minus=27,gap=22)"
        )


class ButtonPort(Protocol):
    """Something that holds at most one ACC button down."""

    def hold(self, button: CruiseButton | None, context: SafetyContext) -> None:
        """Hold `button` from now on (None: release)."""

    def close(self, context: SafetyContext) -> None:
        """Let go of every button for good: the agent is stopping."""


class CanCommandPort:
    """The make's command message on CAN, sent at most once a command period."""

    def __init__(self, car: CarInterface, codec: Codec, sender: SafeSender) -> None:
        self.car = car
        self.codec = codec
        self.sender = sender
        self.frame_id = codec.frame_id(car.command_message)
        self._last_sent_s: float | None = None

    def due(self, now: float) -> bool:
        """True when the next frame should go out."""
        return (
            self._last_sent_s is None
            or now - self._last_sent_s >= PERIOD_SLACK * self.car.command_period_s
        )


class CanButtonPort(CanCommandPort):
    """Holds a button by sending the make's button frame every command period; `latest` gives
    the car's latest signals, which a frame may copy, and `received_at` tells when the car's
    frame of a message now in `latest` was read (`CarStateReader.received_at`), for a make
    whose button frames copy the car's own."""

    def __init__(
        self,
        car: CarInterface,
        codec: Codec,
        sender: SafeSender,
        latest: Callable[[], Mapping[str, Signals]],
        received_at: Callable[[str], float | None],
    ) -> None:
        super().__init__(car, codec, sender)
        self.latest = latest
        self.received_at = received_at
        self._counter = 0
        self._release_frames = 0
        # whether the last frame sent pressed a button: a press the car may still read
        self._pressed_last = False
        self._closed = False
        # the control loop holds, and a stopping agent closes, from whichever thread stops it
        self._lock = threading.Lock()

    def hold(self, button: CruiseButton | None, context: SafetyContext) -> None:
        """Send this period's frame for `button` if one is due."""
        now = context.time_s
        with self._lock:
            if self._closed or (button is None and self._release_frames == 0):
                return
            if not self.due(now):
                return
            if button is None and self._repeats_stale_release(context):
                self._release_frames = 0
                return
            if self._send(button, context):
                self._release_frames = (
                    RELEASE_FRAMES if button is not None else self._release_frames - 1
                )
            elif button is not None:
                # Refused: fall back to releasing (always allowed) on the next period.
                self._release_frames = RELEASE_FRAMES

    def _send(self, button: CruiseButton | None, context: SafetyContext) -> bool:
        """Send one frame pressing `button` (None: all released) through the safety layer;
        True when it went out. A press copying a car frame too old to copy is refused
        (`SafetyLayer.check_copy`); a release is not, as releasing is always allowed (`hold`
        and `close` leave out the releases that only repeat one, `_repeats_stale_release`)."""
        if button is not None:
            refusal = self._stale_copy(context)
            if refusal is not None:
                self.sender.safety.refuse(refusal)
                return False
        latest = self.latest()
        signals = self.car.button_signals(button, latest)
        counter = self.car.command_counter_signal
        if counter is not None:
            signals[counter] = self._next_counter(latest.get(self.car.command_message, {}))
        frame = can.Message(
            arbitration_id=self.frame_id,
            data=self.codec.encode(self.car.command_message, signals),
            is_extended_id=False,
        )
        if not self.sender.send(frame, context):
            return False
        self._last_sent_s = context.time_s
        self._pressed_last = button is not None
        if self.car.command_counter_modulo:
            self._counter = (self._counter + 1) % self.car.command_counter_modulo
        return True

    def _stale_copy(self, context: SafetyContext) -> Refusal | None:
        """Why the car's frame a button frame would copy is too old to copy, or None (also
        for makes whose button frames copy none)."""
        if not self.car.copies_command_frame:
            return None
        return self.sender.safety.check_copy(self.received_at(self.car.command_message), context)

    def _repeats_stale_release(self, context: SafetyContext) -> bool:
        """Whether a release now would only repeat one the car has read, copying a car frame
        too old to copy. The releases after a press are repeated so that the car sees one even
        if a frame is lost, but each copies the driver's pedal and brake too, from a stale copy
        their values of a moment ago. The release ending a press goes out all the same: a
        press must not stand in the last frame the car read."""
        return not self._pressed_last and self._stale_copy(context) is not None

    def _next_counter(self, car_frame: Signals) -> int:
        """The rolling counter of the next frame: one past the car's own last frame of this
        message, as the module receiving the buttons expects of its sender; a counter of our
        own, counting from 0, only while no frame of the car's has been read. Counting on our
        own beside the car's module broke its sequence on nearly every frame sent, which the
        receiving module may drop as invalid."""
        assert self.car.command_counter_signal is not None
        seen = car_frame.get(self.car.command_counter_signal)
        if seen is None or not self.car.command_counter_modulo:
            return self._counter
        return (int(seen) + 1) % self.car.command_counter_modulo

    def close(self, context: SafetyContext) -> None:
        """Send a released frame if a press may still stand in the last frame sent, then
        nothing more. The module reading the buttons acts on the last frame it received, so
        an agent stopping mid-press must end with a release, as every press does (one frame:
        the agent waits no more periods on its way out), unless it would only repeat one the
        car has read from a stale copy (`_repeats_stale_release`) or one it read less than a
        period ago (the rate would refuse it, and that release is the car's last frame)."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if not self._release_frames or self._repeats_stale_release(context):
                return
            if not self._pressed_last and not self.due(context.time_s):
                return
            if not self._send(None, context):
                log.warning("the release frame on closing was not sent: the car may see a press")


class GpioButtonBoard:
    """A button board on GPIO lines (one line per button, active high), as the field team's
    mattHAT spoofed the Rogue's steering-wheel buttons. `write_line(line, level)` is injected:
    on a Raspberry Pi `sysfs_gpio_writer()`, in tests a recorder.

    A line stays high until written low, and the safety layer's longest hold (`max_hold_s`) is
    checked only when the control loop next calls `hold`. So every raised line also gets a
    deadman: a timer thread writes it low once it has been held that long. A control loop that
    stalls (a blocked call, a paused process) then cannot hold + or - for good and walk the set
    speed to the car's maximum; the release is counted in `deadman_releases`. The timer runs on
    the machine's monotonic time, as the car's agent does (`SystemClock`). `close` writes every
    line low and refuses every later press, from whichever thread stops the agent."""

    def __init__(
        self,
        lines: Mapping[CruiseButton, int],
        write_line: Callable[[int, bool], None],
        safety: SafetyLayer,
    ) -> None:
        self.lines = dict(lines)
        self.write_line = write_line
        self.safety = safety
        self.held: CruiseButton | None = None
        self.deadman_releases = 0
        # the control loop, the deadman's timer and a stopping agent all reach the lines
        self._lock = threading.Lock()
        self._deadman: threading.Timer | None = None
        # the button whose hold the deadman ended, until the loop asks for something else
        self._cut: CruiseButton | None = None
        self._closed = False

    def hold(self, button: CruiseButton | None, context: SafetyContext) -> None:
        """Release the previous line, raise the new one if the safety layer allows it."""
        with self._lock:
            if self._closed:
                return
            pressed = frozenset() if button is None else frozenset({button})
            if button is not None and not self.safety.admit_press(pressed, context):
                button = None
            elif button is None:
                self.safety.admit_press(pressed, context)
            if button is not None and button is self._cut:
                button = None  # the same hold the deadman ended: not pressed again
            else:
                self._cut = None
            if button == self.held:
                return
            if self.held is not None:
                self.write_line(self.lines[self.held], False)
                self._cancel_deadman()  # only once the line is low: a failed write keeps it
                self.held = None
            if button is not None:
                # held and deadman first: a write that fails once the level has changed (sysfs
                # can) leaves a line high that the next `hold` or the timer must still lower
                self.held = button
                self._deadman = threading.Timer(self.safety.limits.max_hold_s, self._expire)
                self._deadman.args = (self._deadman,)
                self._deadman.daemon = True
                self._deadman.start()
                self.write_line(self.lines[button], True)

    def close(self, context: SafetyContext) -> None:
        """Write every line low and refuse every later press (the agent is stopping)."""
        with self._lock:
            self._closed = True
            self.safety.admit_press(frozenset(), context)  # a release: always admitted
            self._cancel_deadman()
            self.held = None
            for failure in release_board_lines(self.lines, self.write_line):
                log.error(failure)

    def _cancel_deadman(self) -> None:
        if self._deadman is not None:
            self._deadman.cancel()
            self._deadman = None

    def _expire(self, timer: threading.Timer) -> None:
        """The deadman: end the hold `timer` was started for, if it still stands."""
        with self._lock:
            button = self.held
            if self._deadman is not timer or button is None:
                return  # released, replaced or closed meanwhile
            self.write_line(self.lines[button], False)
            self.held = None
            self._deadman = None
            self._cut = button
            self.deadman_releases += 1
        log.warning(
            "the %s line was held %.1f s with no release from the control loop: written low",
            button.name,
            self.safety.limits.max_hold_s,
        )


def release_board_lines(
    lines: Mapping[CruiseButton, int], write_line: Callable[[int, bool], None]
) -> list[str]:
    """Write every board line low, outside any agent: what a killed agent (SIGKILL, a crash)
    could not do, so the service manager runs it after every exit (`smoothfleet-agent
    --release-buttons`, deploy/smoothfleet-agent.service), and the agent before it starts.
    Returns one message per line that could not be written; the others are written anyway."""
    failures = []
    for button, line in lines.items():
        try:
            write_line(line, False)
        except OSError as error:
            failures.append(f"the {button.value} line (GPIO {line}) was not written low: {error}")
    return failures


def sysfs_gpio_writer(root: Path = Path("/sys/class/gpio")) -> Callable[[int, bool], None]:
    """Drive exported GPIO lines through sysfs (`/sys/class/gpio/gpioN/value`)."""

    def write(line: int, level: bool) -> None:
        (root / f"gpio{line}" / "value").write_text("1" if level else "0")

    return write


class CanAccelPort(CanCommandPort):
    """Sends the make's acceleration request frame every command period."""

    def request(self, accel_mps2: float, context: SafetyContext) -> bool:
        """Send a request for `accel_mps2` (already limited); True when it went out.

        The request releases the stock ACC's standstill (the RAV4's RELEASE_STANDSTILL) only
        when the safety layer says a release may go out (`check_standstill_release`: a fresh
        reading showing no hold), judged from the same car state. Otherwise it keeps the
        standstill, the safe side: the stock ACC holds the stop and the driver resumes. A
        release built regardless would be refused, and every refusal hands the car back: a
        single late PCM_CRUISE frame would end the agent's command."""
        release = self.sender.safety.check_standstill_release(context) is None
        signals = self.car.accel_signals(accel_mps2, release_standstill=release)
        try:
            data = self.codec.encode(self.car.command_message, signals)
        except (ValueError, OverflowError) as error:
            self.sender.safety.refuse(
                Refusal("encode", f"encode: {accel_mps2!r} does not encode ({error})")
            )
            return False
        frame = can.Message(arbitration_id=self.frame_id, data=data, is_extended_id=False)
        sent = self.sender.send(frame, context)
        if sent:
            self._last_sent_s = context.time_s
        return sent

    def stop(self) -> None:
        """Stop requesting (the car's own ACC takes over when the requests stop)."""
        self._last_sent_s = None
