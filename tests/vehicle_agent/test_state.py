"""Car state decoded from DBC-encoded frames, per make, and the real recorded RAV4 frames."""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from vehicle_agent.cars import CarInterface, CarReading, CruiseButton, car_for
from vehicle_agent.cars.toyota import set_speed_mph
from vehicle_agent.codec import Codec, FrameError, codec_for
from vehicle_agent.recording import read_libpanda_csv
from vehicle_agent.state import CarStateReader


def reader_for(key: str, dbc_cache: Path) -> tuple[CarInterface, Codec, CarStateReader]:
    car = car_for(key)
    codec = codec_for(car.dbc_name, car.checksums, dbc_cache)
    return car, codec, CarStateReader(car, codec)


def frame(codec: Codec, name: str, signals: dict[str, float]) -> can.Message:
    return can.Message(
        arbitration_id=codec.frame_id(name),
        data=codec.encode(name, signals),
        is_extended_id=False,
    )


def test_recorded_rav4_speed_frames_decode_to_their_speeds(
    shared_dir: Path, dbc_cache: Path
) -> None:
    _, codec, _ = reader_for("toyota_rav4", dbc_cache)
    recording = read_libpanda_csv(
        shared_dir / "data" / "can" / "can_to_ros_CAN_Message_toyota_msg180.csv"
    )
    # One row of the real file holds "5.90E+90" (a spreadsheet ate the payload): skipped.
    assert len(recording.malformed_rows) == 1
    assert len(recording.frames) == 947
    speeds = []
    for message in recording.frames:
        assert message.arbitration_id == 180
        payload = bytes(message.data)
        name, signals = codec.decode(180, payload)  # the checksum is verified here
        assert name == "SPEED"
        # SPEED: bytes 5-6 big-endian, 0.01 km/h per count (worked from the payload by hand).
        assert signals["SPEED"] == pytest.approx(int.from_bytes(payload[5:7], "big") * 0.01)
        speeds.append(signals["SPEED"])
    # First row 00000000dd057e1c: 0x057e = 1406 -> 14.06 km/h, checksum 0x1c.
    assert speeds[0] == pytest.approx(14.06)
    # A short (8 hex digit) payload, left-padded: 71053062 -> 0x0530 = 13.28 km/h.
    assert 13.28 in [round(s, 2) for s in speeds]
    assert min(speeds) >= 0.0
    assert max(speeds) <= 16.5


def test_recorded_frame_with_a_flipped_bit_fails_its_checksum(dbc_cache: Path) -> None:
    _, codec, _ = reader_for("toyota_rav4", dbc_cache)
    with pytest.raises(FrameError, match="checksum") as error:
        codec.decode(180, bytes.fromhex("00000000dd057f1c"))
    assert error.value.kind == "checksum"
    with pytest.raises(FrameError, match="3 bytes, the DBC says 8"):
        codec.decode(180, b"\x00\x01\x02")


NISSAN_FRAMES = {
    "WHEEL_SPEEDS_FRONT": {"WHEEL_SPEED_FL": 90.0, "WHEEL_SPEED_FR": 90.2},
    "WHEEL_SPEEDS_REAR": {"WHEEL_SPEED_RL": 89.8, "WHEEL_SPEED_RR": 90.0},
    "PRO_PILOT": {"CRUISE_ON": 1, "CRUISE_ACTIVATED": 1, "COUNTER": 0},
    "PROPILOT_HUD": {"SET_SPEED": 58, "FOLLOW_DISTANCE": 2, "LEAD_CAR": 1},
    "CRUISE_THROTTLE": {
        "RES_BUTTON": 1,
        "GAS_PEDAL": 0,
        "USER_BRAKE_PRESSED": 0,
        "NO_BUTTON_PRESSED": 0,
        "COUNTER": 0,
    },
}
GM_FRAMES = {
    "ECMVehicleSpeed": {"VehicleSpeed": 55.9},
    "ECMEngineStatus": {"CruiseActive": 1, "CruiseMainOn": 1, "BrakePressed": 1},
    # 62 mph = 99.78 km/h, quantised to 0.0625 km/h by the DBC.
    "ASCMActiveCruiseControlStatus": {
        "ACCSpeedSetpoint": 62 * 1.609344,
        "ACCGapLevel": 3,
        "ACCLeadCar": 0,
    },
    "ASCMSteeringButton": {
        "ACCButtons": 1,
        "DistanceButton": 1,
        "ACCAlwaysOne": 1,
        "RollingCounter": 0,
    },
    "AcceleratorPedal2": {"AcceleratorPedal2": 40},
}
TOYOTA_FRAMES = {
    "SPEED": {"SPEED": 72.0},
    "PCM_CRUISE": {"CRUISE_ACTIVE": 1, "GAS_RELEASED": 1},
    "PCM_CRUISE_2": {"MAIN_ON": 1, "BRAKE_PRESSED": 0, "SET_SPEED": 100},
    "PCM_CRUISE_SM": {"UI_SET_SPEED": 62, "DISTANCE_LINES": 1},
    "BRAKE_MODULE": {"BRAKE_PRESSED": 0},
    "LEAD_INFO": {"LEAD_LONG_DIST": 35.5, "LEAD_REL_SPEED": -1.25},
}


@pytest.mark.parametrize(
    ("key", "frames", "expected"),
    [
        (
            "nissan_rogue_2018",
            NISSAN_FRAMES,
            CarReading(
                speed_mps=90.0 / 3.6,
                acc_available=True,
                acc_engaged=True,
                acc_speed_setting_mph=58.0,
                acc_gap_setting=2,
                lead_present=True,
                buttons=frozenset({CruiseButton.PLUS}),
            ),
        ),
        (
            "cadillac_xt5",
            GM_FRAMES,
            CarReading(
                speed_mps=55.9 * 0.44704,
                acc_available=True,
                acc_engaged=True,
                acc_speed_setting_mph=62.0,
                acc_gap_setting=3,
                lead_present=False,
                brake_pressed=True,
                gas_pressed=True,
                buttons=frozenset({CruiseButton.GAP}),
            ),
        ),
        (
            "toyota_rav4",
            TOYOTA_FRAMES,
            CarReading(
                speed_mps=20.0,
                acc_available=True,
                acc_engaged=True,
                acc_speed_setting_mph=62.0,  # the display's, in mph: the PCM's 100 km/h
                acc_gap_setting=1,
                lead_present=True,
                lead_distance_m=35.5,
                lead_rel_speed_mps=-1.25,
            ),
        ),
    ],
)
def test_each_make_decodes_its_state_from_dbc_frames(
    key: str, frames: dict[str, dict[str, float]], expected: CarReading, dbc_cache: Path
) -> None:
    _, codec, reader = reader_for(key, dbc_cache)
    for name, signals in frames.items():
        reader.ingest(frame(codec, name, signals), time_s=10.0)
    state = reader.snapshot(10.01)
    assert state.valid, state.problem
    assert state.reading is not None
    assert state.reading.speed_mps == pytest.approx(expected.speed_mps, abs=0.01)
    assert state.reading == CarReading(
        **{
            **{f: getattr(expected, f) for f in CarReading.__slots__},  # type: ignore[attr-defined]
            "speed_mps": state.reading.speed_mps,
            "lead_distance_m": state.reading.lead_distance_m,
            "lead_rel_speed_mps": state.reading.lead_rel_speed_mps,
        }
    )
    if expected.lead_distance_m is not None:
        assert state.reading.lead_distance_m == pytest.approx(expected.lead_distance_m)
        assert state.reading.lead_rel_speed_mps == pytest.approx(expected.lead_rel_speed_mps)
    else:
        assert state.reading.lead_distance_m is None


def fresh_toyota(dbc_cache: Path, time_s: float = 10.0) -> tuple[Codec, CarStateReader]:
    _, codec, reader = reader_for("toyota_rav4", dbc_cache)
    for name, signals in TOYOTA_FRAMES.items():
        reader.ingest(frame(codec, name, signals), time_s)
    return codec, reader


def test_a_message_missing_for_ten_periods_invalidates_the_state(dbc_cache: Path) -> None:
    codec, reader = fresh_toyota(dbc_cache)
    # LEAD_INFO's period is 50 ms: valid at 0.5 s, invalid just after.
    for name, signals in TOYOTA_FRAMES.items():
        if name != "LEAD_INFO":
            reader.ingest(frame(codec, name, signals), 10.45)
    assert reader.snapshot(10.5).valid
    state = reader.snapshot(10.51)
    assert not state.valid
    assert state.problem == "LEAD_INFO missing for 0.51 s"


def test_nothing_received_is_invalid(dbc_cache: Path) -> None:
    _, _, reader = reader_for("nissan_rogue_2018", dbc_cache)
    state = reader.snapshot(0.0)
    assert not state.valid
    assert state.problem == "WHEEL_SPEEDS_FRONT not received yet"


def test_garbage_frames_are_counted_and_invalidate_until_a_good_one(dbc_cache: Path) -> None:
    codec, reader = fresh_toyota(dbc_cache)
    good = frame(codec, "SPEED", {"SPEED": 72.0})
    corrupted = can.Message(
        arbitration_id=180, data=bytes(good.data[:7]) + b"\x00", is_extended_id=False
    )
    truncated = can.Message(arbitration_id=180, data=bytes(good.data[:4]), is_extended_id=False)
    reader.ingest(corrupted, 10.02)
    state = reader.snapshot(10.03)
    assert not state.valid
    assert "SPEED: checksum" in (state.problem or "")
    reader.ingest(good, 10.035)  # a good frame after the refusal was reported: valid again
    assert reader.snapshot(10.036).valid
    reader.ingest(truncated, 10.04)
    reader.ingest(good, 10.045)  # even followed at once by a good frame, the next snapshot
    assert not reader.snapshot(10.05).valid  # reports the truncated one
    assert reader.stats.errors == {"checksum": 1, "length": 1}
    reader.ingest(good, 10.06)
    assert reader.snapshot(10.07).valid


def test_a_speed_no_car_could_reach_invalidates_the_state(dbc_cache: Path) -> None:
    """A SPEED frame with a valid checksum over a wrong number (90 to 200 km/h at once) was
    taken as the car's: an engaged RAV4 then braked itself to a stop on the highway."""
    codec, reader = fresh_toyota(dbc_cache)  # 72 km/h, 20 m/s
    assert reader.snapshot(10.01).valid
    reader.ingest(frame(codec, "SPEED", {"SPEED": 200.0}), 10.02)
    state = reader.snapshot(10.03)
    assert not state.valid
    assert state.problem == "speed 55.6 m/s is out of reach of 20.0 m/s 0.02 s before"
    # The wrong value persisting is refused while no car could have got there: 35.6 m/s at
    # 1 g takes 3.5 s; the agent does not take an accel car over above the fleet's top speed.
    for step in range(1, 30):
        reader.ingest(frame(codec, "SPEED", {"SPEED": 200.0}), 10.02 + 0.1 * step)
        assert not reader.snapshot(10.03 + 0.1 * step).valid


def test_hard_braking_is_the_car_not_a_bad_value(dbc_cache: Path) -> None:
    codec, reader = fresh_toyota(dbc_cache)
    for step in range(1, 21):  # 9 m/s^2 for 2 s, sampled at 100 Hz
        kph = 72.0 - 3.6 * 9.0 * 0.01 * step
        reader.ingest(frame(codec, "SPEED", {"SPEED": kph}), 10.0 + 0.01 * step)
        state = reader.snapshot(10.0 + 0.01 * step)
        assert state.valid, state.problem


def test_a_speed_over_any_makes_top_speed_invalidates_the_state(dbc_cache: Path) -> None:
    codec, reader = fresh_toyota(dbc_cache)
    assert reader.snapshot(10.01).valid
    reader.ingest(frame(codec, "SPEED", {"SPEED": 250.0}), 10.02)  # the DBC's top, 69.4 m/s
    assert reader.snapshot(10.03).problem == (
        "speed 69.4 m/s is out of reach of 20.0 m/s 0.02 s before"
    )
    codec, reader = fresh_toyota(dbc_cache)
    reader.ingest(frame(codec, "SPEED", {"SPEED": 255.0}), 10.02)
    assert (reader.snapshot(10.03).problem or "").startswith("implausible speed 70.8")


def test_unknown_ids_are_counted_and_ignored(dbc_cache: Path) -> None:
    _, reader = fresh_toyota(dbc_cache)
    reader.ingest(
        can.Message(arbitration_id=0x7DF, data=b"\x02\x01\x00", is_extended_id=False), 10.0
    )
    reader.ingest(can.Message(arbitration_id=0x18DAF110, data=b"\x00", is_extended_id=True), 10.0)
    assert reader.stats.unknown_ids == 2
    assert reader.snapshot(10.01).valid


def test_a_stuck_counter_invalidates_the_state(dbc_cache: Path) -> None:
    _, codec, reader = reader_for("nissan_rogue_2018", dbc_cache)
    for name, signals in NISSAN_FRAMES.items():
        reader.ingest(frame(codec, name, signals), 10.0)
    pilot = NISSAN_FRAMES["PRO_PILOT"]
    reader.ingest(frame(codec, "PRO_PILOT", {**pilot, "COUNTER": 1}), 10.05)
    assert reader.snapshot(10.06).valid
    reader.ingest(frame(codec, "PRO_PILOT", {**pilot, "COUNTER": 1}), 10.1)  # repeated
    state = reader.snapshot(10.11)
    assert not state.valid
    assert state.problem == "PRO_PILOT: counter 1 after 1"
    reader.ingest(frame(codec, "PRO_PILOT", {**pilot, "COUNTER": 2}), 10.15)
    assert reader.snapshot(10.16).valid


def test_gm_button_checksum_round_trips_and_detects_corruption(dbc_cache: Path) -> None:
    _, codec, _ = reader_for("cadillac_xt5", dbc_cache)
    for counter in range(4):
        for button in (1, 2, 3, 6):
            data = codec.encode(
                "ASCMSteeringButton",
                {"ACCButtons": button, "ACCAlwaysOne": 1, "RollingCounter": counter},
            )
            _, signals = codec.decode(481, data)
            # 0xF0 + 0xF + counter * 0x4EF - (button - 1) * 16, 12 bits (worked by hand).
            assert (
                signals["SteeringButtonChecksum"]
                == (255 + counter * 0x4EF - (button - 1) * 16) & 0xFFF
            )
    tampered = bytearray(codec.encode("ASCMSteeringButton", {"ACCButtons": 1, "ACCAlwaysOne": 1}))
    tampered[5] ^= 0x60  # flips ACCButtons bits without fixing the checksum
    with pytest.raises(FrameError, match="checksum"):
        codec.decode(481, bytes(tampered))


@pytest.mark.parametrize(
    ("changes", "brake"),
    [
        ({}, False),
        ({"BRAKE_MODULE": {"BRAKE_PRESSED": 1}}, True),  # the bit openpilot and panda read
        ({"PCM_CRUISE_2": {**TOYOTA_FRAMES["PCM_CRUISE_2"], "BRAKE_PRESSED": 1}}, True),
    ],
)
def test_the_rav4s_brake_is_pressed_when_either_message_says_so(
    changes: dict[str, dict[str, float]], brake: bool, dbc_cache: Path
) -> None:
    """The brake was read from opendbc's PCM_CRUISE_2 bit 3 alone, a bit the field team's DBC
    does not define; openpilot and panda read BRAKE_MODULE's."""
    _, codec, reader = reader_for("toyota_rav4", dbc_cache)
    for name, signals in {**TOYOTA_FRAMES, **changes}.items():
        reader.ingest(frame(codec, name, signals), time_s=10.0)
    state = reader.snapshot(10.01)
    assert state.reading is not None
    assert state.reading.brake_pressed is brake


def test_the_rav4s_set_speed_is_the_pcms_whatever_unit_its_display_shows(
    dbc_cache: Path,
) -> None:
    """UI_SET_SPEED is in the unit of the car's display: a car showing km/h, set to 100 km/h,
    was read as set to 100 mph. The PCM's own set speed is always km/h."""
    _, codec, reader = reader_for("toyota_rav4", dbc_cache)
    metric = {**TOYOTA_FRAMES, "PCM_CRUISE_SM": {"UI_SET_SPEED": 100, "DISTANCE_LINES": 1}}
    for name, signals in metric.items():
        reader.ingest(frame(codec, name, signals), time_s=10.0)
    state = reader.snapshot(10.01)
    assert state.reading is not None
    assert state.reading.acc_speed_setting_mph == 62.1


def test_the_rav4s_display_and_pcm_set_speeds_agree_as_loosely_as_the_field_dbc_says() -> None:
    """The field team's DBC: "43 kph are shown as 28mph, so conversion isnt perfect"."""
    assert set_speed_mph(28.0, 43.0) == 28.0
    assert set_speed_mph(60.0, 97.0) == 60.0
    assert set_speed_mph(100.0, 100.0) == 62.1  # a display in km/h
    assert set_speed_mph(0.0, 97.0) == 60.3  # no display figure: the PCM's
