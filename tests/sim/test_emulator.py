"""The car emulator on a virtual CAN bus: the agent's reader decodes its frames for each make,
it reacts to button frames and acceleration requests, and its ACC follows a leader."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from pathlib import Path

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sim.emulator.car import CarEmulator, track_of
from sim.emulator.leaders import ConstantSpeedLeader, SpeedProfileLeader
from sim.emulator.rig import seed_geometry
from vehicle_agent.cars import CruiseButton, car_for
from vehicle_agent.codec import codec_for
from vehicle_agent.state import CarStateReader

_channels = itertools.count()


@pytest.fixture
def channel() -> str:
    return f"emulator-test-{next(_channels)}"


@pytest.fixture
def agent_bus(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


@pytest.fixture
def car_bus(channel: str) -> Iterator[can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel)
    yield bus
    bus.shutdown()


def drain(bus: can.BusABC, reader: CarStateReader, now: float) -> None:
    while (frame := bus.recv(timeout=0)) is not None:
        reader.ingest(frame, now)


@pytest.mark.parametrize(
    "key", ["nissan_rogue", "cadillac_xt5", "toyota_rav4", "nissan_rogue_2018"]
)
def test_agent_reads_the_emulated_car_of_each_make(
    key: str, car_bus: can.BusABC, agent_bus: can.BusABC, dbc_cache: Path
) -> None:
    emulator = CarEmulator(
        key, car_bus, speed_mps=25.0, leader=ConstantSpeedLeader(60.0, 24.0), dbc_cache=dbc_cache
    )
    emulator.driver_engage(set_speed_mph=60)
    car = car_for(key)
    reader = CarStateReader(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    for tick in range(1, 101):
        now = tick * 0.01
        emulator.step(now)
        drain(agent_bus, reader, now)
    state = reader.snapshot(1.0)
    assert state.valid, state.problem
    reading = state.reading
    assert reading is not None
    assert reading.speed_mps == pytest.approx(emulator.speed_mps, abs=0.05)
    assert reading.acc_engaged
    assert reading.acc_available
    assert reading.acc_speed_setting_mph == pytest.approx(60.0)
    assert reading.acc_gap_setting == 3
    assert reading.lead_present
    assert not reading.brake_pressed
    assert reading.buttons == frozenset()
    gap, lead_speed = emulator.lead()
    assert gap is not None
    assert lead_speed is not None
    if key == "toyota_rav4":
        assert reading.lead_distance_m == pytest.approx(gap, abs=0.05)
        assert reading.lead_rel_speed_mps == pytest.approx(
            lead_speed - emulator.speed_mps, abs=0.03
        )
    else:
        assert reading.lead_distance_m is None
    assert reader.stats.errors == {}


@pytest.mark.parametrize("key", ["nissan_rogue_2018", "cadillac_xt5"])
def test_button_frames_move_the_set_speed_and_the_gap(
    key: str, car_bus: can.BusABC, agent_bus: can.BusABC, dbc_cache: Path
) -> None:
    emulator = CarEmulator(key, car_bus, speed_mps=25.0, dbc_cache=dbc_cache)
    emulator.driver_engage(set_speed_mph=60)
    car = car_for(key)
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    counter = 0

    def press(button: CruiseButton | None, start: float, length: float) -> float:
        nonlocal counter
        now = start
        while now < start + length:
            signals = car.button_signals(button, {})
            if car.command_counter_signal:
                signals[car.command_counter_signal] = counter
                counter = (counter + 1) % car.command_counter_modulo
            agent_bus.send(
                can.Message(
                    arbitration_id=codec.frame_id(car.command_message),
                    data=codec.encode(car.command_message, signals),
                    is_extended_id=False,
                )
            )
            now = round(now + 0.05, 3)
            emulator.step(now)
        return now

    now = press(CruiseButton.PLUS, 0.0, 0.25)
    now = press(None, now, 0.25)
    assert emulator.acc.set_speed_mph == 61
    now = press(CruiseButton.MINUS, now, 0.9)
    now = press(None, now, 0.25)
    assert emulator.acc.set_speed_mph == 56
    now = press(CruiseButton.GAP, now, 0.25)
    now = press(None, now, 0.25)
    assert emulator.acc.gap_setting == 2
    assert emulator.agent_bad_frames == 0


def test_acceleration_requests_drive_the_rav4_until_they_stop(
    car_bus: can.BusABC, agent_bus: can.BusABC, dbc_cache: Path
) -> None:
    emulator = CarEmulator("toyota_rav4", car_bus, speed_mps=25.0, dbc_cache=dbc_cache)
    emulator.driver_engage(set_speed_mph=56)  # 25.03 m/s: the stock ACC holds the speed
    car = car_for("toyota_rav4")
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    now = 0.0
    for _ in range(60):  # 2 s of -1 m/s^2 requests at 30 Hz
        agent_bus.send(
            can.Message(
                arbitration_id=codec.frame_id("ACC_CONTROL"),
                data=codec.encode("ACC_CONTROL", car.accel_signals(-1.0, release_standstill=True)),
                is_extended_id=False,
            )
        )
        now += 1 / 30
        emulator.step(now)
    # The powertrain lags 0.3 s: about -1 m/s^2 over the last 1.7 s.
    assert emulator.speed_mps == pytest.approx(25.0 - 1.7, abs=0.2)
    assert emulator.accel_mps2 == pytest.approx(-1.0, abs=0.01)
    for _ in range(60):  # requests stop: the stock ACC accelerates back towards 56 mph
        now += 1 / 30
        emulator.step(now)
    assert emulator.accel_mps2 > 0.3


def test_the_rav4s_pcm_counts_3_s_stopped_then_holds_until_the_driver_resumes(
    car_bus: can.BusABC, agent_bus: can.BusABC, dbc_cache: Path
) -> None:
    """opendbc's PCM_CRUISE CRUISE_STATE: 8 engaged, 11 the 3 s timer once stopped, 7 the
    standstill held for the driver; held, no request moves the car."""
    emulator = CarEmulator("toyota_rav4", car_bus, speed_mps=0.0, dbc_cache=dbc_cache)
    emulator.driver_engage(set_speed_mph=30)
    car = car_for("toyota_rav4")
    reader = CarStateReader(car, codec_for(car.dbc_name, car.checksums, dbc_cache))
    codec = reader.codec
    now = 0.0

    def request(accel_mps2: float, seconds: float) -> list[float]:
        """Requests every 40 ms for `seconds`; the CRUISE_STATE read after each."""
        nonlocal now
        data = codec.encode("ACC_CONTROL", car.accel_signals(accel_mps2, release_standstill=True))
        states = []
        for _ in range(round(seconds / 0.04)):
            frame = can.Message(
                arbitration_id=codec.frame_id("ACC_CONTROL"), data=data, is_extended_id=False
            )
            agent_bus.send(frame)
            now = round(now + 0.04, 3)
            emulator.step(now)
            drain(agent_bus, reader, now)
            states.append(reader.latest["PCM_CRUISE"]["CRUISE_STATE"])
        return states

    waiting = request(-0.5, 2.0)  # stopped 2 s: the timer runs, no hold yet
    assert set(waiting) == {11}
    moving = request(1.0, 1.0)  # moving within the timer: no hold, and the timer is reset
    assert emulator.speed_mps > 0.3
    assert moving[-1] == 8
    request(-3.0, 1.0)  # stopped again
    assert emulator.speed_mps == 0.0
    stopped = request(-0.5, 3.2)
    assert stopped[0] == 11  # the 3 s timer from the stop...
    assert stopped[-1] == 7  # ...then the standstill
    assert emulator.standstill_held
    held = request(1.0, 2.0)  # 2 s of requests to go, RELEASE_STANDSTILL set: no move
    assert emulator.speed_mps == 0.0
    assert set(held) == {7}
    emulator.driver_resume()  # RES
    resumed = request(1.0, 1.0)
    assert emulator.speed_mps > 0.3
    assert resumed[-1] == 8
    # a driver who presses RES by themselves 1 s into a hold (the demo fleet's drivers)
    emulator.driver.resume_after_s = 1.0
    request(-3.0, 1.0)
    waited = request(-0.5, 4.5)
    assert 7 in waited
    assert waited[-1] == 11  # resumed after 1 s, and stopped still: the timer again
    assert not emulator.standstill_held


def test_stock_acc_settles_at_the_gap_settings_time_gap(
    car_bus: can.BusABC, dbc_cache: Path
) -> None:
    emulator = CarEmulator(
        "nissan_rogue",
        car_bus,
        speed_mps=20.0,
        leader=ConstantSpeedLeader(50.0, 20.0),
        dbc_cache=dbc_cache,
    )
    emulator.driver_engage(set_speed_mph=70)
    for tick in range(1, 1201):  # 60 s
        emulator.step(tick * 0.05)
    gap, _ = emulator.lead()
    # Gap control: d = s0 + T v = 4 + 2.0 * 20 at 3 bars.
    assert gap == pytest.approx(44.0, abs=0.5)
    assert emulator.speed_mps == pytest.approx(20.0, abs=0.05)


def test_speed_profile_leader_integrates_its_speeds() -> None:
    leader = SpeedProfileLeader([0.0, 10.0, 20.0], [10.0, 20.0, 20.0], position_m=100.0)
    assert leader.state(10.0) == pytest.approx((250.0, 20.0))
    assert leader.state(5.0) == pytest.approx((100.0 + 5 * 12.5, 15.0))
    assert leader.state(25.0) == pytest.approx((250.0 + 200.0 + 100.0, 20.0))


@given(x_m=st.floats(-500.0, 20_000.0))
def test_the_gps_fix_is_the_corridors_own_position_and_heading(x_m: float) -> None:
    corridor = seed_geometry()
    lat, lon, heading = track_of(corridor).fix(x_m)
    expected_lat, expected_lon = corridor.position(x_m)
    assert lat == pytest.approx(float(expected_lat), abs=1e-9)
    assert lon == pytest.approx(float(expected_lon), abs=1e-9)
    assert heading == float(corridor.heading_deg(x_m)[0])
