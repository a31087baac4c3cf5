"""The safety layer: under random commands no frame reaches the bus out of limits."""

from __future__ import annotations

import itertools
import logging
import math
import time
from collections.abc import Iterator, Mapping
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.vehicle_agent.test_state import TOYOTA_FRAMES
from tests.vehicle_agent.test_state import frame as car_frame
from vehicle_agent.actuators import AccelLimiter
from vehicle_agent.cars import CARS, CarInterface, CarReading, CarState, CruiseButton, car_for
from vehicle_agent.cars.base import Signals
from vehicle_agent.codec import Codec, codec_for
from vehicle_agent.ports import CanAccelPort, CanButtonPort, GpioButtonBoard
from vehicle_agent.safety import Refusal, SafeSender, SafetyContext, SafetyLayer, SafetyLimits
from vehicle_agent.state import CarStateReader

_channels = itertools.count()
READING = CarReading(
    speed_mps=25.0,
    acc_available=True,
    acc_engaged=True,
    acc_speed_setting_mph=56.0,
    acc_gap_setting=3,
    lead_present=False,
)


def car_state(
    time_s: float,
    *,
    valid: bool = True,
    engaged: bool = True,
    speed_mps: float = 25.0,
    setting_mph: float | None = None,
) -> CarState:
    reading = CarReading(
        **{
            **{f: getattr(READING, f) for f in READING.__slots__},  # type: ignore[attr-defined]
            "acc_engaged": engaged,
            "speed_mps": speed_mps,
            **({} if setting_mph is None else {"acc_speed_setting_mph": setting_mph}),
        }
    )
    # what every make's presses are judged from, read at `time_s` (no standstill message, so
    # no release of a standstill, which needs one read)
    received_at = {name: time_s for car in CARS.values() for name in car.press_inputs}
    return CarState(
        time_s,
        valid,
        None if valid else "SPEED missing",
        reading if valid else None,
        received_at if valid else {},
    )


@pytest.fixture
def buses() -> Iterator[tuple[can.BusABC, can.BusABC]]:
    channel = f"safety-{next(_channels)}"
    agent = can.Bus(interface="virtual", channel=channel)
    car = can.Bus(interface="virtual", channel=channel)
    yield agent, car
    agent.shutdown()
    car.shutdown()


def received(bus: can.BusABC) -> list[can.Message]:
    frames = []
    while (frame := bus.recv(timeout=0)) is not None:
        frames.append(frame)
    return frames


accel_requests = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-4.0, max_value=2.0),
)
car_conditions = st.tuples(st.booleans(), st.booleans(), st.floats(0.0, 0.5))


def test_a_line_the_control_loop_stops_releasing_is_written_low_by_the_deadman(
    dbc_cache: Path,
) -> None:
    """A stalled loop never calls `hold` again to end a press: the board's own timer does, at
    the safety layer's longest hold, and the same hold is not raised again when the loop
    comes back; a new press after a release is."""
    car = car_for("nissan_rogue_2018")
    limits = SafetyLimits(max_hold_s=0.2)
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache), limits)
    levels: dict[int, bool] = {}
    board = GpioButtonBoard({CruiseButton.PLUS: 17}, levels.__setitem__, safety)
    board.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    assert levels[17]
    deadline = time.monotonic() + 5.0
    while levels[17] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not levels[17]
    assert board.deadman_releases == 1
    # the loop comes back still asking for the hold it began: not pressed again
    board.hold(CruiseButton.PLUS, SafetyContext(0.15, car_state(0.15)))
    assert not levels[17]
    # released, then a new press after the press interval: raised, and let go in time
    board.hold(None, SafetyContext(0.3, car_state(0.3)))
    board.hold(CruiseButton.PLUS, SafetyContext(0.8, car_state(0.8)))
    assert levels[17]
    board.hold(None, SafetyContext(0.9, car_state(0.9)))
    time.sleep(0.3)
    assert board.deadman_releases == 1  # a press the loop ended is no deadman release


def test_a_line_whose_raise_failed_after_it_went_high_is_still_written_low(
    dbc_cache: Path,
) -> None:
    """A write can fail after the level changed (sysfs reports an error the pin has already
    taken). The board cannot tell, so it treats the line as held: the loop's release lowers it,
    and so does the deadman when the loop never comes back."""
    car = car_for("nissan_rogue_2018")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    levels: dict[int, bool] = {}

    def write_that_fails_going_high(line: int, level: bool) -> None:
        levels[line] = level
        if level:
            raise OSError("EIO")

    board = GpioButtonBoard({CruiseButton.PLUS: 17}, write_that_fails_going_high, safety)
    with pytest.raises(OSError, match="EIO"):
        board.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    board.hold(None, SafetyContext(0.05, car_state(0.05)))
    assert not levels[17]

    stalled_safety = SafetyLayer(
        car, codec_for(car.dbc_name, car.checksums, dbc_cache), SafetyLimits(max_hold_s=0.2)
    )
    stalled = GpioButtonBoard({CruiseButton.PLUS: 27}, write_that_fails_going_high, stalled_safety)
    with pytest.raises(OSError, match="EIO"):
        stalled.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    deadline = time.monotonic() + 5.0
    while levels[27] and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not levels[27]
    assert stalled.deadman_releases == 1


def test_a_closed_board_writes_every_line_low_and_presses_nothing_more(dbc_cache: Path) -> None:
    car = car_for("nissan_rogue_2018")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    writes: list[tuple[int, bool]] = []
    board = GpioButtonBoard(
        {CruiseButton.PLUS: 17, CruiseButton.MINUS: 27},
        lambda line, level: writes.append((line, level)),
        safety,
    )
    board.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    board.close(SafetyContext(0.5, car_state(0.5)))
    board.hold(CruiseButton.MINUS, SafetyContext(1.0, car_state(1.0)))
    assert writes == [(17, True), (17, False), (27, False)]
    assert board.held is None


class ButtonPortRig(NamedTuple):
    """A button car's port on the agent's bus, with what a test reads beside it."""

    car: CarInterface
    codec: Codec
    safety: SafetyLayer
    copy: CarCopy
    port: CanButtonPort


def button_port(key: str, agent_bus: can.BusABC, dbc_cache: Path) -> ButtonPortRig:
    """The make's button port sending through its own safety layer, copying `CarCopy`."""
    car = car_for(key)
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    copy = CarCopy(car)
    port = CanButtonPort(car, codec, SafeSender(agent_bus, safety), copy.latest, copy.received_at)
    return ButtonPortRig(car, codec, safety, copy, port)


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(steps=st.lists(st.tuples(accel_requests, car_conditions), min_size=1, max_size=80))
def test_no_acceleration_frame_leaves_out_of_limits(
    steps: list[tuple[float, tuple[bool, bool, float]]],
    buses: tuple[can.BusABC, can.BusABC],
    dbc_cache: Path,
) -> None:
    agent_bus, car_bus = buses
    received(car_bus)
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    port = CanAccelPort(car, codec, SafeSender(agent_bus, safety))
    sent_at: list[tuple[float, float]] = []
    for index, (request, (valid, engaged, state_age)) in enumerate(steps):
        now = index / 30
        context = SafetyContext(now, car_state(now - state_age, valid=valid, engaged=engaged), 0.0)
        if port.request(request, context):  # straight from a "controller", no limiter
            sent_at.append((now, request))
            assert valid
            assert engaged
            assert state_age <= 0.25
    frames = received(car_bus)
    assert len(frames) == len(sent_at)
    previous: tuple[float, float] | None = None
    for frame, (now, _) in zip(frames, sent_at, strict=True):
        assert frame.arbitration_id == codec.frame_id("ACC_CONTROL")
        _, signals = codec.decode(frame.arbitration_id, frame.data)
        accel = signals["ACCEL_CMD"]
        assert math.isfinite(accel)
        assert -3.0 <= accel <= 1.5
        assert signals["CANCEL_REQ"] == 0
        assert signals["RELEASE_STANDSTILL"] == 0  # no PCM_CRUISE read: no release
        if previous is not None and now - previous[0] <= 0.5:
            dt = now - previous[0]
            assert dt >= 0.8 / 30 - 1e-9
            assert previous[1] - 5.0 * dt - 0.011 <= accel <= previous[1] + 2.5 * dt + 0.011
        elif previous is None:
            assert -5.0 / 30 - 0.011 <= accel <= 2.5 / 30 + 0.011  # from a measured 0 m/s^2
        previous = (now, accel)


buttons = st.one_of(st.none(), st.sampled_from(list(CruiseButton)))
# How long before a frame is built the car's own frame of the command message was read.
copy_ages = st.sampled_from([0.0, 0.05, 0.1, 0.15, 0.45])


class CarCopy:
    """The car's own frame of the command message as the agent's reader keeps it: the signals
    a button frame may copy, and when they were read (`read_s`, None: not yet)."""

    def __init__(self, car: CarInterface, read_s: float | None = None) -> None:
        self.frames = {car.command_message: dict(car.button_signals(None, {}))}
        self.read_s = read_s

    def latest(self) -> Mapping[str, Signals]:
        return self.frames

    def received_at(self, name: str) -> float | None:
        return self.read_s


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    key=st.sampled_from(["nissan_rogue_2018", "cadillac_xt5"]),
    steps=st.lists(
        st.tuples(buttons, st.booleans(), st.booleans(), copy_ages), min_size=1, max_size=120
    ),
)
def test_no_button_frame_leaves_out_of_limits(
    key: str,
    steps: list[tuple[CruiseButton | None, bool, bool, float]],
    buses: tuple[can.BusABC, can.BusABC],
    dbc_cache: Path,
) -> None:
    agent_bus, car_bus = buses
    received(car_bus)
    car, codec, _, copy, port = button_port(key, agent_bus, dbc_cache)
    held: frozenset[CruiseButton] = frozenset()
    press_started: float | None = None
    last_onset: float | None = None
    released_at: float | None = None
    for index, (button, valid, engaged, copy_age) in enumerate(steps):
        now = index * 0.05
        copy.read_s = now - copy_age
        port.hold(button, SafetyContext(now, car_state(now, valid=valid, engaged=engaged)))
        frames = received(car_bus)  # the virtual bus delivers at once: these left just now
        assert len(frames) <= 1
        for frame in frames:
            assert frame.arbitration_id == codec.frame_id(car.command_message)
            _, signals = codec.decode(frame.arbitration_id, frame.data)  # checksum valid
            pressed = car.pressed_buttons(signals)
            assert pressed <= {CruiseButton.PLUS, CruiseButton.MINUS, CruiseButton.GAP}
            assert len(pressed) <= 1
            if pressed:
                assert valid
                assert engaged
                # the Nissan's copy of the car's frame (pedals, brake) at most 2 periods old
                assert not car.copies_command_frame or copy_age <= 0.1
                if not held:
                    assert last_onset is None or now - last_onset >= 0.45 - 1e-9
                    # a real release between two presses, not a one-frame blip
                    assert released_at is None or now - released_at >= 0.15 - 1e-9
                    last_onset = press_started = now
                else:
                    assert pressed == held
                    assert press_started is not None
                    assert now - press_started <= SafetyLimits().max_hold_s + 1e-9
            elif held:
                released_at = now
            elif car.copies_command_frame:
                assert copy_age <= 0.1  # from a stale copy, only the release ending a press
            held = pressed


@pytest.mark.parametrize(
    ("changes", "reason"),
    [
        ({"ACCButtons": 4}, "ACCButtons code 4 is no known button"),
        ({"ACCButtons": 0}, "ACCButtons code 0 is no known button"),
        ({"LKAButton": 1}, "LKAButton pressed"),
        ({"DriveModeButton": 1}, "DriveModeButton pressed"),
    ],
)
def test_a_button_frame_setting_what_is_no_known_press_is_no_release(
    changes: dict[str, int], reason: str, dbc_cache: Path
) -> None:
    """Whatever pressed_buttons did not list passed as a release, which is always allowed: a
    frame pressing lane keeping or the drive mode, or an unknown code, went out with the ACC
    off and the car state invalid."""
    car = car_for("cadillac_xt5")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    invalid = SafetyContext(1.0, car_state(1.0, valid=False, engaged=False))
    release = codec.encode(car.command_message, car.button_signals(None, {}))
    frame_id = codec.frame_id(car.command_message)
    assert (
        safety.check(
            can.Message(arbitration_id=frame_id, data=release, is_extended_id=False), invalid
        )
        is None
    )
    data = codec.encode(car.command_message, {**car.button_signals(None, {}), **changes})
    refusal = safety.check(
        can.Message(arbitration_id=frame_id, data=data, is_extended_id=False), invalid
    )
    assert refusal is not None
    assert refusal.kind == "button"
    assert reason in refusal.detail


@pytest.mark.parametrize(
    "changes",
    [
        {"ACCEL_CMD_ALT": 1.5},  # a second acceleration field, out of the limits' sight
        {"DISTANCE": 1},  # the following-distance button
        {"ACC_MALFUNCTION": 1},  # a fault shown on the dash
        {"PERMIT_BRAKING": 0},  # braking forbidden
        {"ACC_TYPE": 2},  # the low-speed lockout
        {"ALLOW_LONG_PRESS": 2},
        {"RADAR_DIRTY": 1},
    ],
)
def test_an_acceleration_frame_setting_anything_but_the_request_is_refused(
    changes: dict[str, float], dbc_cache: Path
) -> None:
    """The layer checked only ACCEL_CMD, CANCEL_REQ and RELEASE_STANDSTILL of the RAV4's
    ACC_CONTROL, and passed any value in its other signals; the agent's frame builder sets
    them to one value each, and a frame with another asks the car for what the agent never
    does."""
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    context = SafetyContext(1.0, car_state(1.0), 0.0)
    frame_id = codec.frame_id(car.command_message)
    request = car.accel_signals(0.0, release_standstill=False)
    plain = codec.encode(car.command_message, request)
    frame = can.Message(arbitration_id=frame_id, data=plain, is_extended_id=False)
    assert SafetyLayer(car, codec).check(frame, context) is None
    data = codec.encode(car.command_message, {**request, **changes})
    frame = can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)
    refusal = SafetyLayer(car, codec).check(frame, context)
    assert refusal is not None
    assert refusal.kind == "signal"
    assert next(iter(changes)) in refusal.detail


@pytest.mark.parametrize(
    ("pedal", "shown"),
    [({"USER_BRAKE_PRESSED": 1}, "the brake pressed"), ({"GAS_PEDAL": 200}, "the gas pedal")],
)
def test_a_rogue_press_in_a_frame_showing_the_drivers_pedal_is_refused(
    pedal: dict[str, int], shown: str, dbc_cache: Path
) -> None:
    """A Rogue button frame copies the car's pedal and brake. A press beside the driver's
    pedal went out whenever the agent's override check had not yet seen the pedal; the release
    carrying it still goes out, as every release does."""
    car = car_for("nissan_rogue_2018")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    context = SafetyContext(1.0, car_state(1.0))
    frame_id = codec.frame_id(car.command_message)

    def frame(button: CruiseButton | None) -> can.Message:
        data = codec.encode(car.command_message, {**car.button_signals(button, {}), **pedal})
        return can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)

    refusal = safety.check(frame(CruiseButton.PLUS), context)
    assert refusal is not None
    assert refusal.kind == "driver"
    assert shown in refusal.detail
    assert safety.check(frame(None), context) is None


def test_only_the_release_ending_a_press_may_come_sooner_than_the_rate(dbc_cache: Path) -> None:
    """A release refused for its rate left a stopping agent's press standing in the car's last
    frame. The one release after a press passes however soon; another right behind it, and a
    press, keep the rate."""
    car = car_for("nissan_rogue_2018")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    frame_id = codec.frame_id(car.command_message)

    def frame(button: CruiseButton | None) -> can.Message:
        data = codec.encode(car.command_message, car.button_signals(button, {}))
        return can.Message(arbitration_id=frame_id, data=data, is_extended_id=False)

    assert safety.admit(frame(CruiseButton.PLUS), SafetyContext(1.0, car_state(1.0)))
    safety.idle()  # the agent hands back: the car still read the press last
    assert safety.admit(frame(None), SafetyContext(1.01, car_state(1.01)))
    assert not safety.admit(frame(None), SafetyContext(1.02, car_state(1.02)))
    assert safety.refused["rate"] == 1


@pytest.mark.parametrize(("held", "refused"), [(True, True), (False, False)])
def test_no_frame_releases_a_standstill_held_for_the_driver(
    held: bool, refused: bool, dbc_cache: Path
) -> None:
    """The frame builder alone kept RELEASE_STANDSTILL at 0 while the RAV4's PCM holds the car
    for the driver's resume: a builder that set it would have driven off unattended."""
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    state = car_state(1.0)
    assert state.reading is not None
    reading = replace(state.reading, standstill_held=held)
    context = SafetyContext(
        1.0, replace(state, reading=reading, received_at={"PCM_CRUISE": 1.0}), 0.0
    )
    releasing = car.accel_signals(0.0, release_standstill=True)
    data = codec.encode(car.command_message, releasing)
    frame = can.Message(
        arbitration_id=codec.frame_id(car.command_message), data=data, is_extended_id=False
    )
    refusal = safety.check(frame, context)
    assert (refusal is not None and refusal.kind == "standstill") is refused
    assert (refusal is None) is not refused


def test_no_frame_releases_a_standstill_from_a_pcm_cruise_over_two_periods_old(
    buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """The layer refused a release only while the car state's reading showed the PCM's hold,
    whatever the age of the PCM_CRUISE it was read from: the car state stays valid on one 10
    periods (0.33 s) old, time enough for the PCM to have stopped and held since. A release
    now needs a PCM_CRUISE read at most 2 of its periods ago, showing no hold."""
    agent_bus, car_bus = buses
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    reader = CarStateReader(car, codec)
    safety = SafetyLayer(car, codec)
    sender = SafeSender(agent_bus, safety)
    releasing = can.Message(
        arbitration_id=codec.frame_id(car.command_message),
        data=codec.encode(car.command_message, car.accel_signals(0.0, release_standstill=True)),
        is_extended_id=False,
    )
    engaged = {**TOYOTA_FRAMES["PCM_CRUISE"], "CRUISE_STATE": 8}  # "adaptive engaged"
    for step in range(7):  # 0 .. 0.2 s, PCM_CRUISE only at 0 s
        now = step * car.command_period_s
        for name, signals in {**TOYOTA_FRAMES, "PCM_CRUISE": engaged}.items():
            if name != "PCM_CRUISE" or step == 0:
                reader.ingest(car_frame(codec, name, signals), now)
        if step == 0:
            assert sender.send(releasing, SafetyContext(now, reader.snapshot(now), 0.0))
    stale = SafetyContext(now, reader.snapshot(now), 0.0)
    assert stale.car_state.valid, stale.car_state.problem
    assert safety.check(releasing, stale) == Refusal(
        "standstill", "releases a standstill from a PCM_CRUISE 0.20 s old"
    )
    assert not sender.send(releasing, stale)
    assert len(received(car_bus)) == 1
    assert safety.refused == {"standstill": 1}


def test_a_press_needs_a_real_release_before_it(
    buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """The press rate was counted from onset to onset only: a 1.1 s hold, one 50 ms release
    frame and another 1.1 s hold all passed, which a car that misses the blip reads as one
    2.25 s hold, past the 1.2 s of a second 5 mph step."""
    agent_bus, car_bus = buses
    car, codec, safety, copy, port = button_port("nissan_rogue_2018", agent_bus, dbc_cache)
    now = 0.0
    while now < 1.1 - 1e-9:  # the longest hold allowed
        copy.read_s = now
        port.hold(CruiseButton.PLUS, SafetyContext(now, car_state(now)))
        now = round(now + 0.05, 2)
    port.hold(None, SafetyContext(now, car_state(now)))  # one release frame
    for _ in range(2):  # pressed again at once: refused
        now = round(now + 0.05, 2)
        copy.read_s = now
        port.hold(CruiseButton.PLUS, SafetyContext(now, car_state(now)))
    assert safety.refused["press"] == 2
    now = copy.read_s = 1.35  # released for the sequencer's 0.25 s: let through
    port.hold(CruiseButton.PLUS, SafetyContext(now, car_state(now)))
    pressed = [
        car.pressed_buttons(codec.decode(frame.arbitration_id, frame.data)[1])
        for frame in received(car_bus)
    ]
    assert sum(1 for buttons in pressed if buttons) == 22 + 1


@pytest.mark.parametrize("key", ["nissan_rogue_2018", "cadillac_xt5"])
def test_no_press_of_plus_sets_a_button_car_over_the_fleets_top_speed(
    key: str, buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """A controller whose request skipped the paper's clip (asking for 90 mph) had the ACC set
    to 90 mph and the car driven there: the acceleration frames had a top speed, the presses
    none."""
    agent_bus, _ = buses
    _, _, safety, copy, port = button_port(key, agent_bus, dbc_cache)

    def press(now: float, button: CruiseButton | None, setting_mph: float) -> bool:
        """Whether the frame holding `button` went out (was not refused)."""
        copy.read_s = now
        before = sum(safety.refused.values())
        port.hold(button, SafetyContext(now, car_state(now, setting_mph=setting_mph)))
        return sum(safety.refused.values()) == before

    assert press(0.0, CruiseButton.PLUS, 72.0)  # to 73: let through
    assert press(0.5, CruiseButton.PLUS, 73.0)  # held on, a step past the top: let through
    assert press(0.55, None, 73.0)
    assert not press(1.0, CruiseButton.PLUS, 73.0)  # a new press at the top: refused
    assert safety.refused == {"setting": 1}
    assert press(1.5, CruiseButton.MINUS, 80.0)  # slowing from over the top: let through
    assert press(1.75, None, 80.0)
    assert press(2.5, CruiseButton.PLUS, 60.0)
    assert not press(2.55, CruiseButton.PLUS, 75.0)  # held on 2 mph past the top: refused
    assert safety.refused == {"setting": 2}


@pytest.mark.parametrize("key", ["nissan_rogue_2018", "cadillac_xt5"])
def test_button_frames_count_on_from_the_cars_own_counter(
    key: str, buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """The port counted 0, 1, 2, 3 on its own beside the car's module sending the same
    message: the receiving module saw the sequence broken on nearly every frame sent."""
    agent_bus, car_bus = buses
    car = car_for(key)
    assert car.command_counter_signal is not None
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    copy = CarCopy(car)
    port = CanButtonPort(
        car,
        codec,
        SafeSender(agent_bus, SafetyLayer(car, codec)),
        copy.latest,
        copy.received_at,
    )
    for step, car_counter in enumerate([2, 3, 0, 1, 1]):
        copy.frames[car.command_message][car.command_counter_signal] = car_counter
        now = copy.read_s = 0.05 * step
        port.hold(CruiseButton.PLUS, SafetyContext(now, car_state(now)))
        (frame,) = received(car_bus)
        _, signals = codec.decode(frame.arbitration_id, frame.data)
        assert signals[car.command_counter_signal] == (car_counter + 1) % 4


@pytest.mark.parametrize("stops", [False, True])
def test_from_a_stale_copy_only_the_release_ending_a_press_goes_out(
    stops: bool, buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """Every Rogue button frame copies the car's CRUISE_THROTTLE, pedals and brake included.
    Once its frames stopped reaching the agent, the press was refused, but the port went on to
    send its repeated releases from the stale copy (or one more when the agent stopped), each
    telling the car the driver's inputs of a moment ago. The release ending the press still
    goes out: no press may stand in the last frame the car read."""
    agent_bus, car_bus = buses
    car, codec, safety, copy, port = button_port("nissan_rogue_2018", agent_bus, dbc_cache)
    copy.read_s = 0.0  # the car's last CRUISE_THROTTLE the agent reads
    sent: list[tuple[float, frozenset[CruiseButton]]] = []
    for step in range(9 if not stops else 5):
        now = round(0.05 * step, 2)
        port.hold(CruiseButton.PLUS if now < 0.2 else None, SafetyContext(now, car_state(now)))
        for frame in received(car_bus):
            sent.append(
                (now, car.pressed_buttons(codec.decode(frame.arbitration_id, frame.data)[1]))
            )
    port.close(SafetyContext(0.45, car_state(0.45)))
    assert received(car_bus) == []
    plus = frozenset({CruiseButton.PLUS})
    assert sent == [(0.0, plus), (0.05, plus), (0.1, plus), (0.2, frozenset())]
    assert safety.refused == {"copy": 1}  # the press at 0.15 s


def test_an_agent_stopping_just_after_a_release_sends_no_repeat_the_rate_refuses(
    buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """A release repeats for a few periods so the car sees one even if a frame is lost. The
    agent stopping in the same period as a release tried one more: the safety layer refused it
    for the rate ("rate: sent 0.000 s after the previous frame", seen stopping the demo's fleet
    in `bench.fleet_step`) and the port warned that the car may see a press, which it could
    not: the car had just read the release. Now the repeat waits for its period, and a port
    stopping before it is due sends nothing and says nothing."""
    agent_bus, car_bus = buses
    _, _, safety, copy, port = button_port("nissan_rogue_2018", agent_bus, dbc_cache)
    copy.read_s = 0.0
    port.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    copy.read_s = 0.05
    port.hold(None, SafetyContext(0.05, car_state(0.05)))  # the release ending the press
    assert len(received(car_bus)) == 2
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.ports"):
        port.close(SafetyContext(0.05, car_state(0.05)))
    assert received(car_bus) == []
    assert safety.refused == {}
    assert "may see a press" not in caplog.text


def test_refusals_are_counted_with_their_reason(dbc_cache: Path) -> None:
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    context = SafetyContext(1.0, car_state(1.0), 0.0)
    good = codec.encode("ACC_CONTROL", car.accel_signals(0.05, release_standstill=False))
    frame_id = codec.frame_id("ACC_CONTROL")
    assert (
        safety.check(can.Message(arbitration_id=frame_id, data=good, is_extended_id=False), context)
        is None
    )
    checks = {
        "id 0xb4 is not ACC_CONTROL": can.Message(
            arbitration_id=180, data=good, is_extended_id=False
        ),
        "4 bytes, ACC_CONTROL has 8": can.Message(
            arbitration_id=frame_id, data=good[:4], is_extended_id=False
        ),
        "does not decode: ACC_CONTROL: checksum": can.Message(
            arbitration_id=frame_id, data=good[:7] + bytes([good[7] ^ 1]), is_extended_id=False
        ),
    }
    for reason, frame in checks.items():
        assert str(safety.check(frame, context)).startswith(reason)
    # counted by kind, never by a word of the text ("4 bytes ..." is no kind "4")
    for frame in checks.values():
        assert not safety.admit(frame, context)
    assert safety.refused == {"id": 1, "length": 1, "decode": 1}
    too_hard = codec.encode("ACC_CONTROL", car.accel_signals(-3.5, release_standstill=False))
    assert safety.check(
        can.Message(arbitration_id=frame_id, data=too_hard, is_extended_id=False), context
    ) == Refusal("acceleration", "acceleration -3.5 m/s^2 outside [-3.0, 1.5]")
    disengaged = SafetyContext(1.0, car_state(1.0, engaged=False), 0.0)
    assert safety.check(
        can.Message(arbitration_id=frame_id, data=good, is_extended_id=False), disengaged
    ) == Refusal("ACC", "ACC not engaged by the driver")
    stale = SafetyContext(1.0, car_state(0.5), 0.0)
    assert safety.check(
        can.Message(arbitration_id=frame_id, data=good, is_extended_id=False), stale
    ) == Refusal("car state", "car state 0.50 s old")


def test_the_car_state_is_aged_when_the_command_leaves_not_when_the_pass_began(
    dbc_cache: Path,
) -> None:
    car = car_for("nissan_rogue_2018")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    sent_at = [0.1]
    safety = SafetyLayer(car, codec, clock=lambda: sent_at[0])
    context = SafetyContext(0.0, car_state(0.0))  # the pass read the car at 0 s
    assert safety.check_press(frozenset({CruiseButton.PLUS}), context) is None
    sent_at[0] = 0.3  # ... and reached the button 0.3 s later
    assert safety.check_press(frozenset({CruiseButton.PLUS}), context) == Refusal(
        "car state", "car state 0.30 s old"
    )


def test_a_press_copies_only_a_car_frame_read_within_two_periods(dbc_cache: Path) -> None:
    car = car_for("nissan_rogue_2018")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    checked_at = [0.1]
    safety = SafetyLayer(car, codec, clock=lambda: checked_at[0])
    context = SafetyContext(0.1, car_state(0.1))
    assert safety.check_copy(None, context) == Refusal(
        "copy", "no CRUISE_THROTTLE of the car's to copy"
    )
    assert safety.check_copy(0.0, context) is None  # 2 periods old
    checked_at[0] = 0.16  # the pass stalled after reading the car
    assert safety.check_copy(0.0, context) == Refusal(
        "copy", "the car's CRUISE_THROTTLE to copy is 0.16 s old"
    )


def test_gpio_board_presses_only_what_the_safety_layer_allows(dbc_cache: Path) -> None:
    car = car_for("nissan_rogue_2018")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    writes: list[tuple[int, bool]] = []
    board = GpioButtonBoard(
        {
            CruiseButton.PLUS: 17,
            CruiseButton.MINUS: 27,
            CruiseButton.GAP: 22,
            CruiseButton.CANCEL: 5,
        },
        lambda line, level: writes.append((line, level)),
        safety,
    )
    board.hold(CruiseButton.PLUS, SafetyContext(0.0, car_state(0.0)))
    board.hold(CruiseButton.PLUS, SafetyContext(0.25, car_state(0.25)))
    board.hold(None, SafetyContext(0.3, car_state(0.3)))
    board.hold(CruiseButton.MINUS, SafetyContext(0.35, car_state(0.35)))  # too soon: refused
    board.hold(CruiseButton.CANCEL, SafetyContext(1.0, car_state(1.0)))  # never the agent's
    board.hold(CruiseButton.GAP, SafetyContext(2.0, car_state(2.0, engaged=False)))
    board.hold(CruiseButton.GAP, SafetyContext(3.0, car_state(3.0)))
    assert writes == [(17, True), (17, False), (22, True)]
    assert safety.refused == {"press": 1, "button": 1, "ACC": 1}


def test_a_held_button_is_let_go_before_the_car_takes_a_second_long_step(
    dbc_cache: Path,
) -> None:
    """The fleet's cars step a held + or - by 5 mph every 0.6 s: held to 1.2 s, one hold would
    move the setting 10 mph. The safety layer lets a hold last only up to 1.1 s."""
    car = car_for("nissan_rogue_2018")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    levels: dict[int, bool] = {}
    board = GpioButtonBoard({CruiseButton.PLUS: 17}, levels.__setitem__, safety)
    released_at = None
    for step in range(26):  # 0 .. 1.25 s, every 0.05 s
        now = step * 0.05
        board.hold(CruiseButton.PLUS, SafetyContext(now, car_state(now)))
        if released_at is None and not levels[17]:
            released_at = now
    assert released_at is not None
    assert 0.9 < released_at < 2 * 0.6


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    measured=st.floats(min_value=-6.0, max_value=4.0),
    requests=st.lists(st.floats(min_value=-4.0, max_value=2.0), min_size=1, max_size=60),
    # up to the safety layer's tolerance over the fleet's top speed (73 + 2 mph = 33.53 m/s):
    # beyond it the layer refuses a request still positive (the next test)
    speed_mps=st.floats(min_value=0.0, max_value=33.5),
)
def test_what_the_limiter_lets_through_the_safety_layer_accepts(
    measured: float,
    requests: list[float],
    speed_mps: float,
    buses: tuple[can.BusABC, can.BusABC],
    dbc_cache: Path,
) -> None:
    """Taking over a car that already accelerates outside [-3, 1.5] m/s^2 (a hard launch, an
    emergency stop), at any speed up to the fleet's top speed and a little over it: the limiter
    starts from that measurement, and none of its requests may be refused by the independent
    check, which would hand the car back for nothing."""
    agent_bus, car_bus = buses
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    port = CanAccelPort(car, codec, SafeSender(agent_bus, SafetyLayer(car, codec)))
    limiter = AccelLimiter()
    limiter.reset(measured, 0.0)
    for index, request in enumerate(requests, start=1):
        now = index * car.command_period_s
        value = limiter.limit(now, request, speed_mps=speed_mps)
        assert -3.0 <= value <= 1.5
        context = SafetyContext(now, car_state(now, speed_mps=speed_mps), measured)
        assert port.request(value, context)
    assert len(received(car_bus)) == len(requests)


def test_the_limiter_keeps_the_car_under_the_fleets_top_speed() -> None:
    """Worked by hand: top 73 mph = 32.63392 m/s, approached over 2 s, left at 1 m/s^2 at most."""
    top = 73 * 0.44704
    limits = AccelLimiter().limits
    assert limits.top_speed_mps == pytest.approx(top)
    for speed, expected in [
        (20.0, 1.5),  # 45 mph: the request is the limiter's own bound, untouched
        (top - 1.0, 0.5),  # (32.634 - 31.634) / 2
        (top, 0.0),
        (top + 0.5, -0.25),
        (top + 10.0, -1.0),  # 95 mph: back to the top gently, no emergency braking
    ]:
        limiter = AccelLimiter()  # no previous request: no jerk limit
        assert limiter.limit(0.0, 1.5, speed_mps=speed) == pytest.approx(expected)
    # A braking the controller asks for is never softened by the bound.
    assert AccelLimiter().limit(0.0, -2.5, speed_mps=top + 10.0) == -2.5


def test_the_speed_a_car_gains_while_its_requests_ease_off() -> None:
    """Worked by hand: from +1 m/s^2 the requests fall to 0 in 1 / 5 s; counted at +1 m/s^2
    throughout, that is 0.2 m/s. From +2 m/s^2, 0.8 m/s; a braking car gains nothing."""
    limits = AccelLimiter().limits
    assert limits.speed_gain_while_easing_off_mps(1.0) == pytest.approx(0.2)
    assert limits.speed_gain_while_easing_off_mps(2.0) == pytest.approx(0.8)
    assert limits.speed_gain_while_easing_off_mps(-1.0) == 0.0


def test_no_frame_asks_for_more_speed_well_over_the_fleets_top_speed(
    buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """A request built without the limiter, positive at 76 mph, is refused and never sent; a
    braking one there, and a positive one within 2 mph of the top, go out."""
    agent_bus, car_bus = buses
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    port = CanAccelPort(car, codec, SafeSender(agent_bus, safety))
    mph = 0.44704

    def request(index: int, accel: float, speed_mph: float) -> bool:
        now = index * car.command_period_s
        return port.request(
            accel, SafetyContext(now, car_state(now, speed_mps=speed_mph * mph), accel)
        )

    assert not request(1, 0.1, 76.0)
    assert safety.refused["top speed"] == 1
    assert request(2, -0.5, 76.0)
    assert request(40, 0.1, 74.5)  # over 0.5 s later: no jerk reference to the braking
    assert len(received(car_bus)) == 2


def test_the_jerk_check_judges_from_a_recent_request_over_the_time_elapsed(
    buses: tuple[can.BusABC, can.BusABC], dbc_cache: Path
) -> None:
    """The jerk band is the last request's, over the time since it, while it is under 0.5 s
    old; older, or after the agent let go (`idle`), the car's measured acceleration over one
    period (RAV4: 2.5 m/s^3 up, 5 down, 0.01 m/s^2 tolerance, 1/30 s)."""
    agent_bus, _ = buses
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    port = CanAccelPort(car, codec, SafeSender(agent_bus, safety))
    period = car.command_period_s

    def request(now: float, accel: float, measured: float) -> bool:
        return port.request(accel, SafetyContext(now, car_state(now), measured))

    # two seconds after -2.5 the reference is the car's 0: +1.5 in one period is a jerk step
    assert request(0.0, -2.5, -2.5)
    assert not request(2.0, 1.5, 0.0)
    # a frame late by two periods: 0 -> +0.2 in 0.1 s is 2 m/s^3 (within 0.1 x 2.5 + 0.01)
    assert request(10.0, 0.0, 0.0)
    assert request(10.1, 0.2, 0.0)
    # a frame early: +0.09 after 0.8 of a period is 3.4 m/s^3 (over 0.8 x 2.5 / 30 + 0.01)
    assert request(20.0, 0.0, 0.0)
    assert not request(20.0 + 0.8 * period, 0.09, 0.0)
    # handed back just after braking, taken over again: judged from the car, not the -2.5
    assert request(30.0, -2.5, -2.5)
    safety.idle()
    assert request(30.1, 0.05, 0.0)
    assert safety.refused["jerk"] == 2
