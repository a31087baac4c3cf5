"""The 2023 Nissan Rogue, the paper's majority car: its CAN-FD frames read byte by byte, its
buttons pressed by a GPIO board wired to the switches, and no frame of the agent's on its bus."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from sim.emulator.car import BOARD_LINES, CarEmulator
from sim.emulator.rig import Rig, rig
from vehicle_agent.agent import Agent
from vehicle_agent.bus import open_bus
from vehicle_agent.cars import CARS, CarReading, CarState, CruiseButton, car_for
from vehicle_agent.clock import ManualClock
from vehicle_agent.codec import codec_for
from vehicle_agent.engage import Mode
from vehicle_agent.ports import ButtonBoardRequired, GpioButtonBoard
from vehicle_agent.safety import SafetyContext, SafetyLayer
from vehicle_agent.spool import PingSpool
from vehicle_agent.state import CarStateReader

CONTROL_PERIOD_S = 0.1
# The slowest of the car's watched messages (CRUISE, WHEEL_BUTTONS, ACC_HUD): 100 ms.
SLOWEST_PERIOD_S = 0.1


def payload(length: int, bytes_at: dict[int, int]) -> bytes:
    data = bytearray(length)
    for index, value in bytes_at.items():
        data[index] = value
    return bytes(data)


def fd_frame(frame_id: int, data: bytes) -> can.Message:
    return can.Message(arbitration_id=frame_id, data=data, is_extended_id=False, is_fd=True)


def test_hand_built_frames_read_as_the_field_teams_dbc_lays_them_out(dbc_cache: Path) -> None:
    """Each payload set byte by byte from the DBC's Motorola layouts (start bit = byte * 8 + bit,
    most significant bit first), not by the codec under test."""
    car = car_for("nissan_rogue")
    reader = CarStateReader(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    # SPEED (303, 12 bytes): 12 bits from bit 77 (byte 9, bit 5) at 0.048 km/h. Raw 2083 =
    # 0b100000_100011: byte 9 holds the top six (0b100000 = 0x20), byte 10 the low six in its
    # bits 7..2 (0b100011 << 2 = 0x8C). 2083 x 0.048 = 99.984 km/h.
    speed = payload(12, {9: 0x20, 10: 0x8C})
    # CRUISE (308, 64 bytes): CRUISE_STATE, 4 bits from bit 306 (byte 38, bit 2): 12 (engaged)
    # = 0b1100, so 0b110 in byte 38 and 0 in byte 39's bit 7; CRUISE_ENGAGED at bit 321 (byte
    # 40, bit 1).
    cruise = payload(64, {38: 0b110, 40: 0b10})
    # WHEEL_BUTTONS (1119, 20 bytes): ACC_BTNS, 3 bits from bit 61 (byte 7, bits 5..3): 1 resume.
    buttons = payload(20, {7: 1 << 3})
    # ACC_HUD (1487, 48 bytes): SYSTEM_ON bit 94 (byte 11, bit 6), MINICAR bit 142 (byte 17,
    # bit 6), SET_SPEED 7 bits from bit 158 (byte 19, bits 6..0) = 58 mph, SET_DISTANCE 2 bits
    # from bit 166 (byte 20, bits 6..5) = 2 bars.
    hud = payload(48, {11: 0x40, 17: 0x40, 19: 58, 20: 2 << 5})
    for frame_id, data in ((303, speed), (308, cruise), (1119, buttons), (1487, hud)):
        reader.ingest(fd_frame(frame_id, data), 10.0)
    state = reader.snapshot(10.0)
    assert state.valid, state.problem
    assert state.reading == CarReading(
        speed_mps=pytest.approx(2083 * 0.048 / 3.6),  # type: ignore[arg-type]
        acc_available=True,
        acc_engaged=True,
        acc_speed_setting_mph=58.0,
        acc_gap_setting=2,
        lead_present=True,
        buttons=frozenset({CruiseButton.PLUS}),
    )
    # 14: engaged with the driver's gas pressed (0b1110: 0b111 in byte 38); 4: a standstill the
    # stock ACC holds for the driver to resume (0b0100: 0b010)
    reader.ingest(fd_frame(308, payload(64, {38: 0b111, 40: 0b10})), 10.05)
    reading = reader.snapshot(10.05).reading
    assert reading is not None
    assert reading.gas_pressed
    assert not reading.standstill_held
    reader.ingest(fd_frame(308, payload(64, {38: 0b010, 40: 0b10})), 10.1)
    reading = reader.snapshot(10.1).reading
    assert reading is not None
    assert reading.standstill_held
    assert not reading.gas_pressed
    # 0: off; no set speed is read while ACC is not engaged
    reader.ingest(fd_frame(308, payload(64, {})), 10.15)
    reading = reader.snapshot(10.15).reading
    assert reading is not None
    assert (reading.acc_available, reading.acc_engaged) == (False, False)
    assert reading.acc_speed_setting_mph is None


def test_the_2018_frames_are_not_the_2023_cars() -> None:
    """A make, model and year from the roster picks the interface of that year's frames."""
    assert car_for("Nissan", "Rogue", 2023).key == "nissan_rogue"
    assert car_for("Nissan", "Rogue", 2021).key == "nissan_rogue"
    assert car_for("Nissan", "Rogue", 2019).key == "nissan_rogue_2018"
    assert car_for("Nissan", "Rogue").key == "nissan_rogue"  # the fleet's
    assert car_for("nissan_rogue").can_fd


def test_without_a_button_board_the_agent_refuses_to_drive_the_car(
    tmp_path: Path, dbc_cache: Path
) -> None:
    bus = can.Bus(interface="virtual", channel="rogue-2023-no-board")
    try:
        with pytest.raises(ButtonBoardRequired, match="SMOOTHFLEET_AGENT_BUTTON_BOARD"):
            Agent(
                vehicle_id="SF-001",
                car=car_for("nissan_rogue"),
                bus=bus,
                clock=ManualClock(),
                gps=None,  # type: ignore[arg-type]
                spool=PingSpool(tmp_path / "spool.sqlite"),
                dbc_cache=dbc_cache,
            )
    finally:
        bus.shutdown()


def test_the_safety_layer_lets_no_frame_onto_the_cars_bus(dbc_cache: Path) -> None:
    """The car refused injected commands (paper): a button frame built anyway, well formed,
    is refused, so it cannot collide with the wheel's own WHEEL_BUTTONS."""
    car = car_for("nissan_rogue")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    safety = SafetyLayer(car, codec)
    press = can.Message(
        arbitration_id=1119,
        data=codec.encode("WHEEL_BUTTONS", {"ACC_BTNS": 1}),
        is_extended_id=False,
        is_fd=True,
    )
    assert not safety.admit(
        press, SafetyContext(time_s=1.0, car_state=CarState(1.0, True, None, None))
    )
    assert safety.refused == {"id": 1}


def test_the_emulated_car_counts_injected_button_frames_and_acts_on_none(
    dbc_cache: Path,
) -> None:
    """As the real one refused them (paper): so a test's count of the agent's frames means
    something for this car too."""
    car_bus = can.Bus(interface="virtual", channel="rogue-2023-inject")
    agent_bus = can.Bus(interface="virtual", channel="rogue-2023-inject")
    try:
        emulator = CarEmulator("nissan_rogue", car_bus, speed_mps=25.0, dbc_cache=dbc_cache)
        emulator.driver_engage(set_speed_mph=60)
        codec = codec_for("nissan_rogue_2023", {}, dbc_cache)
        now = 0.0
        for _ in range(10):  # + held 0.5 s in frames every 50 ms, then released
            agent_bus.send(fd_frame(1119, codec.encode("WHEEL_BUTTONS", {"ACC_BTNS": 1})))
            now = round(now + 0.05, 3)
            emulator.step(now)
        for _ in range(10):
            agent_bus.send(fd_frame(1119, codec.encode("WHEEL_BUTTONS", {"ACC_BTNS": 0})))
            now = round(now + 0.05, 3)
            emulator.step(now)
        assert emulator.agent_frames == 20
        assert emulator.acc.set_speed_mph == 60
    finally:
        car_bus.shutdown()
        agent_bus.shutdown()


def test_a_can_fd_bus_carries_the_cars_64_byte_frames() -> None:
    sender = open_bus("virtual:rogue-2023-fd", fd=True)
    receiver = open_bus("virtual:rogue-2023-fd", fd=True)
    try:
        sender.send(fd_frame(308, payload(64, {38: 0b110, 40: 0b10})))
        received = receiver.recv(timeout=1.0)
        assert received is not None
        assert (received.arbitration_id, len(received.data), received.is_fd) == (308, 64, True)
    finally:
        sender.shutdown()
        receiver.shutdown()


def engaged(r: Rig) -> bool:
    return r.agent.state.mode is Mode.ENGAGED


def test_the_board_wired_to_the_switches_walks_the_set_speed_and_gap_to_the_request(
    tmp_path: Path, dbc_cache: Path
) -> None:
    # simple: target 60 mph, gap 1 bar; the car sees the board's presses as its own buttons
    with rig(
        "nissan_rogue",
        tmp_path,
        dbc_cache,
        controller="simple",
        params={"gap_setting": 1},
        speed_mps=22.352,
    ) as r:
        assert isinstance(r.agent.buttons, GpioButtonBoard)
        assert r.agent.buttons.lines == BOARD_LINES
        r.emulator.driver_engage(set_speed_mph=50)
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason
        r.run(
            60.0,
            until=lambda: r.emulator.acc.set_speed_mph == 60 and r.emulator.acc.gap_setting == 1,
        )
        assert (r.emulator.acc.set_speed_mph, r.emulator.acc.gap_setting) == (60, 1)
        presses = r.agent.sequencer.presses
        r.run(10.0)
        assert r.agent.sequencer.presses == presses  # done: no press after the request is met
        assert engaged(r)
        assert not r.agent.sequencer.stalled
        assert r.agent.safety.refused == {}
        assert r.agent.safety.sent == 0  # no frame on the car's bus...
        assert r.emulator.agent_frames == 0  # ...as the car counts them, acted on or not
        assert r.agent.reader.stats.errors == {}


@pytest.mark.parametrize("action", ["brake", "gas", "cancel"])
def test_the_driver_takes_the_car_back_within_a_cruise_frame(
    action: str, tmp_path: Path, dbc_cache: Path
) -> None:
    """No brake pedal is read: the brake cancels the stock ACC, which CRUISE reports; the gas
    shows as its own cruise state; the cancel button in WHEEL_BUTTONS (and the ACC it cancels)."""
    with rig("nissan_rogue", tmp_path, dbc_cache, controller="simple") as r:
        r.emulator.driver_engage(set_speed_mph=50)
        r.run(5.0, until=lambda: engaged(r))
        assert engaged(r), r.agent.state.reason
        touched_at = r.clock.monotonic()
        if action == "brake":
            r.emulator.driver_brake(True)
        elif action == "gas":
            r.emulator.driver_gas(True)
        else:
            r.emulator.driver_buttons(CruiseButton.CANCEL)
        r.run(3.0, until=lambda: not engaged(r))
        assert not engaged(r)
        assert r.clock.monotonic() - touched_at <= SLOWEST_PERIOD_S + CONTROL_PERIOD_S
        if action == "gas":
            assert r.agent.state.mode is Mode.OVERRIDDEN


def test_the_safety_layer_refuses_a_press_while_the_stock_acc_holds_a_standstill(
    dbc_cache: Path,
) -> None:
    car = car_for("nissan_rogue")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    held = CarReading(
        speed_mps=0.0,
        acc_available=True,
        acc_engaged=True,
        acc_speed_setting_mph=30.0,
        acc_gap_setting=3,
        lead_present=True,
        standstill_held=True,
    )
    read = dict.fromkeys(car.messages, 1.0)
    context = SafetyContext(time_s=1.0, car_state=CarState(1.0, True, None, held, read))
    assert not safety.admit_press(frozenset({CruiseButton.PLUS}), context)
    assert safety.refused == {"standstill": 1}
    assert safety.admit_press(frozenset(), context)  # letting go always is


def test_no_press_is_judged_from_an_engagement_frame_gone_stale(dbc_cache: Path) -> None:
    """The car state stays valid on a CRUISE 10 periods (1 s) old, and the 2023 Rogue shows the
    driver's brake only as CRUISE_ENGAGED 0: a press judged from a CRUISE 0.95 s old could land
    on an ACC the driver has just cancelled (the board's - is SET, which engages it again). A
    press waits for a CRUISE and an ACC_HUD at most 2 periods old; a release never waits."""
    car = car_for("nissan_rogue")
    safety = SafetyLayer(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    engaged = CarReading(
        speed_mps=25.0,
        acc_available=True,
        acc_engaged=True,
        acc_speed_setting_mph=56.0,
        acc_gap_setting=3,
        lead_present=True,
    )
    read = {"SPEED": 1.0, "WHEEL_BUTTONS": 1.0, "ACC_HUD": 1.0, "CRUISE": 0.05}
    stale = SafetyContext(time_s=1.0, car_state=CarState(1.0, True, None, engaged, read))
    assert not safety.admit_press(frozenset({CruiseButton.MINUS}), stale)
    assert safety.refused == {"car state": 1}
    assert safety.admit_press(frozenset(), stale)

    fresh = {**read, "CRUISE": 0.85}  # 0.15 s: one frame late
    context = SafetyContext(time_s=1.0, car_state=CarState(1.0, True, None, engaged, fresh))
    assert safety.admit_press(frozenset({CruiseButton.MINUS}), context)


@pytest.mark.parametrize("key", sorted(CARS))
def test_every_button_make_names_the_frames_a_press_is_judged_from(key: str) -> None:
    car = CARS[key]
    assert (car.actuation == "acc") == bool(car.press_inputs)
    assert set(car.press_inputs) <= set(car.messages)
