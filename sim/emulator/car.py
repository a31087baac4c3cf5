"""The emulated car on a CAN bus: its make's DBC frames out, button frames and acceleration
requests in, a stock ACC in between, and a leader ahead.

Stepped by whoever owns the clock (`step(now)`): a test or the simulator advances simulation
time, the demo its own loop. Frames go out at each message's nominal period (the agent's table
in vehicle_agent.cars, scaled by `period_scale` to lighten a hundred emulated cars: the car
state tolerates 10 missed periods, but a press is judged only from frames at most 2 periods old
(`SafetyLayer.check_press`), so a scale of 3 already has presses refused; nothing scales it).

The car's own button message reports every button held, the driver's and the agent's alike, as a
button board pressing the real switches would; the agent tells its own presses apart. A board is
wired to the emulated switches through `board_line` (lines `BOARD_LINES`); a car that acts on no
injected button frame (the 2023 Rogue) ignores the agent's, as the real one did.
"""

from __future__ import annotations

import bisect
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import can

from contract.corridor import CorridorGeometry
from sim.emulator.acc import StockAcc, StockAccParams
from sim.emulator.frames import FRAMES, CarSnapshot
from sim.emulator.leaders import ConstantSpeedLeader, Leader
from vehicle_agent.cars import CarInterface, CruiseButton, car_for
from vehicle_agent.codec import FrameError, codec_for
from vehicle_agent.gps import GpsFix
from vehicle_agent.ports import ButtonPort, GpioButtonBoard
from vehicle_agent.safety import SafetyLayer

log = logging.getLogger(__name__)

# The powertrain's response to an acceleration command: a first-order lag (s).
ACTUATOR_LAG_S = 0.3
# Agent commands older than this many command periods are no longer obeyed.
COMMAND_TIMEOUT_PERIODS = 3
MAX_SUBSTEP_S = 0.02
# What the driver's feet do: brake pedal (m/s^2) and gas pedal (m/s^2).
DRIVER_BRAKE_MPS2 = -2.5
DRIVER_GAS_MPS2 = 1.0
# The RAV4's PCM once the car is stopped with ACC engaged (opendbc's toyota_nodsu_pt, PCM_CRUISE
# CRUISE_STATE: "if standstill is requested will switch to state 11 (3 sec timer), after timer is
# elapsed will switch into state 7 (standstill)"): it then holds the car until the driver
# resumes (RES or the gas), whatever acceleration is requested. Whether the real PCM also takes
# ACC_CONTROL's RELEASE_STANDSTILL then is not known here (openpilot drives off with it); the
# agent never sets it once it has read the hold, and the emulated PCM leaves the hold to the
# driver alone, so a frame in flight as the hold begins cannot end it.
PCM_HOLD_AFTER_S = 3.0
# The makes whose stock ACC holds a standstill for the driver: the RAV4's PCM, the 2023 Rogue
# (CRUISE_STATE 4, "standstill" in the field team's libpanda) and the XT5 (AcceleratorPedal2
# CruiseState 4, opendbc's "Standstill"), which report it, and the 2018-20 Rogue, whose frames
# do not (the emulated car sends nothing of it either); their delays before the hold are not
# known: the RAV4's 3 s is assumed. A press of + (RES) by anyone, the
# driver or a button board on the switches, resumes the hold, as RES does on the car; a + held
# since before the hold began is no new press.
HOLDS_STANDSTILL = frozenset({"toyota_rav4", "nissan_rogue", "nissan_rogue_2018", "cadillac_xt5"})
# Below this speed the car is stopped (m/s).
STOPPED_MPS = 0.01
# The GPIO lines of the button board wired to an emulated car's switches (docs/agent.md's
# example wiring).
BOARD_LINES = {CruiseButton.PLUS: 17, CruiseButton.MINUS: 27, CruiseButton.GAP: 22}
# Payloads kept per message for frames whose signals repeat (a counter's cycle, a constant HUD):
# a hundred emulated cars re-encoding identical frames was a tenth of the demo fleet's step.
PAYLOADS_PER_MESSAGE = 64


@dataclass(frozen=True)
class Track:
    """A corridor's vertices in plain floats: one GPS fix costs a bisection, not numpy calls
    (the emulator makes a fix for every agent tick of every car of the demo fleet)."""

    x_m: list[float]
    lat: list[float]
    lon: list[float]
    heading_deg: list[float]  # of each step between vertices

    def fix(self, x_m: float) -> tuple[float, float, float]:
        """(lat, lon, heading) at `x_m`, as `CorridorGeometry.position` and `heading_deg` give
        them (clamped to the ends, linear between vertices)."""
        step = min(max(bisect.bisect_right(self.x_m, x_m) - 1, 0), len(self.heading_deg) - 1)
        start, end = self.x_m[step], self.x_m[step + 1]
        fraction = min(max((x_m - start) / (end - start), 0.0), 1.0)
        lat = self.lat[step] + fraction * (self.lat[step + 1] - self.lat[step])
        lon = self.lon[step] + fraction * (self.lon[step + 1] - self.lon[step])
        return lat, lon, self.heading_deg[step]


@lru_cache(maxsize=8)
def track_of(corridor: CorridorGeometry) -> Track:
    """The plain-float track of a corridor (shared by every emulated car on it)."""
    return Track(
        corridor.x_m.tolist(),
        corridor.lat.tolist(),
        corridor.lon.tolist(),
        corridor.heading_deg(corridor.x_m[:-1]).tolist(),
    )


@dataclass
class Driver:
    """The driver's inputs; `resume_after_s`, how long after a standstill hold begins the driver
    resumes (RES) by themselves (None: only when `driver_resume()` is called)."""

    brake: bool = False
    gas: bool = False
    buttons: frozenset[CruiseButton] = frozenset()
    resume_after_s: float | None = None


class CarEmulator:
    """One emulated car of a given make on `bus`.

    `frame_epoch_s`, where given, stamps each frame sent with the wall time an agent on a
    simulated clock reads (`ManualClock.now`), as SocketCAN stamps a frame on receipt, so the
    agent dates the frames on its own time line; the bus must then keep the stamps (python-can's
    virtual bus with `preserve_timestamps=True`). Without it the bus stamps the host's time, which
    an agent on the machine's clock (`SystemClock`) reads.
    """

    def __init__(
        self,
        car: CarInterface | str,
        bus: can.BusABC,
        *,
        speed_mps: float = 0.0,
        position_m: float = 0.0,
        leader: Leader | None = None,
        acc_params: StockAccParams | None = None,
        corridor: CorridorGeometry | None = None,
        lane: int | None = None,
        start_s: float = 0.0,
        period_scale: float = 1.0,
        dbc_cache: Path | None = None,
        frame_epoch_s: Callable[[], float] | None = None,
    ) -> None:
        self.car = car if isinstance(car, CarInterface) else car_for(car)
        self.frame_epoch_s = frame_epoch_s
        self.bus = bus
        self.codec = codec_for(self.car.dbc_name, self.car.checksums, dbc_cache)
        self.frames = FRAMES[self.car.key]
        self.acc = StockAcc(acc_params)
        self.driver = Driver()
        self.speed_mps = speed_mps
        self.accel_mps2 = 0.0
        self.position_m = position_m
        self.leader = leader
        self.corridor = corridor
        self.lane = lane
        self.time_s = start_s
        self.period_scale = period_scale
        self.muted: set[str] = set()
        self.sent = 0
        self.agent_frames = 0
        self.agent_bad_frames = 0
        self._command_id = self.codec.frame_id(self.car.command_message)
        self._frame_ids = {name: self.codec.frame_id(name) for name in self.frames}
        self._next_send = dict.fromkeys(self.frames, start_s)
        self._counters = dict.fromkeys(self.frames, 0)
        self._payloads: dict[str, dict[tuple[tuple[str, float], ...], bytes]] = {
            name: {} for name in self.frames
        }
        self._agent_buttons: frozenset[CruiseButton] = frozenset()
        self._board_lines_high: set[int] = set()
        self._agent_command_s = -math.inf
        self._agent_accel = 0.0
        # the stock ACC's standstill (HOLDS_STANDSTILL): when the car stopped engaged, when the
        # hold began
        self._stopped_since_s: float | None = None
        self._held_since_s: float | None = None
        self._buttons_before: frozenset[CruiseButton] = frozenset()

    # The driver -----------------------------------------------------------------------------

    def driver_engage(self, set_speed_mph: int | None = None) -> None:
        """The driver sets ACC (at the current speed, or at `set_speed_mph`)."""
        self.acc.main_on = True
        self.acc.engage(self.speed_mps)
        if set_speed_mph is not None:
            self.acc.set_speed_mph = set_speed_mph

    def driver_brake(self, pressed: bool) -> None:
        """Brake pedal: pressing it disengages the ACC."""
        self.driver.brake = pressed
        if pressed:
            self.acc.cancel()

    def driver_gas(self, pressed: bool) -> None:
        """Gas pedal: overrides the ACC while pressed."""
        self.driver.gas = pressed

    def driver_resume(self) -> None:
        """The driver resumes a standstill the stock ACC holds (the RAV4's RES, whose set speed
        stays as it was)."""
        self._held_since_s = None
        self._stopped_since_s = None

    @property
    def standstill_held(self) -> bool:
        """Whether the stock ACC holds the car stopped for the driver to resume."""
        return self._held_since_s is not None

    def driver_buttons(self, *buttons: CruiseButton) -> None:
        """The steering-wheel buttons the driver holds from now on."""
        self.driver.buttons = frozenset(buttons)

    def board_line(self, line: int, level: bool) -> None:
        """A GPIO line of the button board wired to the switches (`BOARD_LINES`) goes high
        (pressing its button) or low: the `write_line` of a `GpioButtonBoard`."""
        if level:
            self._board_lines_high.add(line)
        else:
            self._board_lines_high.discard(line)

    def _board_buttons(self) -> frozenset[CruiseButton]:
        return frozenset(b for b, line in BOARD_LINES.items() if line in self._board_lines_high)

    # The road ahead --------------------------------------------------------------------------

    def cut_in(self, gap_m: float, speed_mps: float) -> None:
        """A car changes into the lane `gap_m` ahead and drives on at `speed_mps`."""
        self.leader = ConstantSpeedLeader(self.position_m + gap_m, speed_mps, self.time_s)

    def lead(self) -> tuple[float | None, float | None]:
        """(gap in m, leader speed in m/s) of the leader, or (None, None)."""
        if self.leader is None:
            return None, None
        position, speed = self.leader.state(self.time_s)
        return position - self.position_m, speed

    def gps_fix(self, time_s: float) -> GpsFix | None:
        """Where the car is, as a GPS receiver would report it (needs a corridor)."""
        if self.corridor is None:
            return None
        lat, lon, heading = track_of(self.corridor).fix(self.position_m)
        return GpsFix(
            time_s=time_s,
            lat=lat,
            lon=lon,
            speed_mps=self.speed_mps,
            heading_deg=heading,
            satellites=12,
            lane=self.lane,
        )

    # Simulation -----------------------------------------------------------------------------

    def step(self, now: float) -> None:
        """Read the agent's frames, advance the car to `now`, send the frames that are due."""
        self._receive(now)
        held = self.driver.buttons | self._agent_buttons_at(now) | self._board_buttons()
        self.acc.buttons(now, held, self.speed_mps, brake_pressed=self.driver.brake)
        while self.time_s < now - 1e-9:
            dt = min(MAX_SUBSTEP_S, now - self.time_s)
            self._advance(dt)
        self.time_s = now
        self._update_standstill(now, held)
        self._buttons_before = held
        self._send_due(now, held)

    def _update_standstill(self, now: float, held: frozenset[CruiseButton]) -> None:
        """The stock ACC's standstill (`HOLDS_STANDSTILL`): 3 s stopped with ACC engaged, then
        held until resumed (a press of +, `driver_resume`, the gas, or
        `Driver.resume_after_s`)."""
        if self.car.key not in HOLDS_STANDSTILL or not self.acc.engaged:
            self._stopped_since_s = self._held_since_s = None
            return
        if self._held_since_s is not None:
            resume = self.driver.resume_after_s
            if (
                self.driver.gas
                or CruiseButton.PLUS in held - self._buttons_before
                or (resume is not None and now - self._held_since_s >= resume)
            ):
                self.driver_resume()
            return
        if self.speed_mps > STOPPED_MPS:
            self._stopped_since_s = None
        elif self._stopped_since_s is None:
            self._stopped_since_s = now
        elif now - self._stopped_since_s >= PCM_HOLD_AFTER_S:
            self._held_since_s = now

    def _agent_command_fresh(self, now: float) -> bool:
        return now - self._agent_command_s <= COMMAND_TIMEOUT_PERIODS * self.car.command_period_s

    def _agent_buttons_at(self, now: float) -> frozenset[CruiseButton]:
        return self._agent_buttons if self._agent_command_fresh(now) else frozenset()

    def _receive(self, now: float) -> None:
        while True:
            frame = self.bus.recv(timeout=0)
            if frame is None:
                return
            if frame.arbitration_id != self._command_id:
                continue
            try:
                _, signals = self.codec.decode(frame.arbitration_id, frame.data)
            except FrameError:
                self.agent_bad_frames += 1
                continue
            self.agent_frames += 1  # counted, whether or not the car acts on it
            if not self.car.accepts_button_frames:
                continue
            self._agent_command_s = now
            if self.car.actuation == "accel":
                self._agent_accel = self.car.commanded_accel(signals)
            else:
                self._agent_buttons = self.car.pressed_buttons(signals)

    def commanded_accel(self) -> float:
        """What the powertrain is asked for now: driver, agent request or stock ACC."""
        if self.driver.brake:
            return DRIVER_BRAKE_MPS2
        gap, lead_speed = self.lead()
        params = self.acc.params
        if not self.acc.engaged:
            return DRIVER_GAS_MPS2 if self.driver.gas else 0.0
        if self.car.actuation == "accel" and self._agent_command_fresh(self.time_s):
            command = min(max(self._agent_accel, params.min_accel_mps2), params.max_accel_mps2)
        else:
            command = self.acc.accel(self.speed_mps, gap, lead_speed)
        return max(command, DRIVER_GAS_MPS2) if self.driver.gas else command

    def _advance(self, dt: float) -> None:
        if self.standstill_held and not self.driver.gas:
            # the PCM holds the car on its brakes: stopped, whatever crawl was left
            self.speed_mps = self.accel_mps2 = 0.0
            self.time_s += dt
            return
        command = self.commanded_accel()
        self.accel_mps2 += (command - self.accel_mps2) * min(dt / ACTUATOR_LAG_S, 1.0)
        self.speed_mps = max(self.speed_mps + self.accel_mps2 * dt, 0.0)
        if self.speed_mps == 0.0:
            self.accel_mps2 = max(self.accel_mps2, 0.0)
        self.position_m += self.speed_mps * dt
        self.time_s += dt

    def snapshot(self, held: frozenset[CruiseButton]) -> CarSnapshot:
        """What the car's ECUs report now."""
        gap, lead_speed = self.lead()
        sensed = (
            gap is not None
            and lead_speed is not None
            and 0.0 < gap <= (self.acc.params.sensor_range_m)
        )
        return CarSnapshot(
            speed_mps=self.speed_mps,
            acc_main_on=self.acc.main_on,
            acc_engaged=self.acc.engaged,
            set_speed_mph=self.acc.set_speed_mph,
            gap_setting=self.acc.gap_setting,
            lead_present=sensed,
            lead_distance_m=gap if sensed else None,
            lead_rel_speed_mps=(lead_speed - self.speed_mps)
            if sensed and lead_speed is not None
            else None,
            brake_pressed=self.driver.brake,
            gas_pressed=self.driver.gas,
            buttons=held,
            standstill_timer=self._stopped_since_s is not None and not self.standstill_held,
            standstill_held=self.standstill_held,
        )

    def _send_due(self, now: float, held: frozenset[CruiseButton]) -> None:
        snapshot: CarSnapshot | None = None
        for name, build in self.frames.items():
            if now + 1e-9 < self._next_send[name]:
                continue
            rule = self.car.messages[name]
            period = rule.period_s * self.period_scale
            self._next_send[name] = max(self._next_send[name] + period, now + period / 2)
            if name in self.muted:
                continue
            snapshot = snapshot or self.snapshot(held)
            signals = build(snapshot)
            if rule.counter_signal is not None:
                signals[rule.counter_signal] = self._counters[name]
                self._counters[name] = (self._counters[name] + 1) % rule.counter_modulo
            data = self._payload(name, signals)
            self.send_raw(
                can.Message(
                    arbitration_id=self._frame_ids[name],
                    data=data,
                    is_extended_id=False,
                    is_fd=len(data) > 8,
                    timestamp=0.0 if self.frame_epoch_s is None else self.frame_epoch_s(),
                )
            )

    def _payload(self, name: str, signals: dict[str, float]) -> bytes:
        """The encoded frame, from the message's recent payloads when its signals repeat."""
        payloads = self._payloads[name]
        key = tuple(signals.items())
        data = payloads.get(key)
        if data is None:
            if len(payloads) >= PAYLOADS_PER_MESSAGE:
                payloads.clear()
            data = payloads[key] = self.codec.encode(name, signals)
        return data

    def send_raw(self, frame: can.Message) -> None:
        """Put any frame on the bus (tests use it for garbage)."""
        self.bus.send(frame)
        self.sent += 1


def board_wired_to(emulator: CarEmulator) -> Callable[[SafetyLayer], ButtonPort] | None:
    """The agent's button board wired to `emulator`'s switches, for a car that acts on no
    button frame (the 2023 Rogue, as the field team fitted it); None for the others, whose
    agent presses their buttons in CAN frames."""
    if emulator.car.actuation != "acc" or emulator.car.accepts_button_frames:
        return None

    def board(safety: SafetyLayer) -> ButtonPort:
        return GpioButtonBoard(BOARD_LINES, emulator.board_line, safety)

    return board
