"""How the agent dates a CAN frame by its receive stamp (`vehicle_agent.clock.frame_age`); the
emulated car's stamps on a simulated clock are tested by the stalled pass in test_agent.py."""

from __future__ import annotations

import time

import can

from vehicle_agent.clock import SystemClock, frame_age


def test_a_frame_is_as_old_as_its_stamp_says_never_less_than_new() -> None:
    assert frame_age(1_000.5, 1_000.0) == 0.5
    assert frame_age(1_000.0, 1_000.5) == 0.0  # stamped ahead: the wall clock stepped back
    assert frame_age(1_000.0, 0.0) == 0.0  # no interface stamped it


def test_the_system_clock_dates_a_frame_the_virtual_bus_stamped_on_the_host() -> None:
    sender = can.Bus(interface="virtual", channel="clock-test")
    receiver = can.Bus(interface="virtual", channel="clock-test")
    try:
        sender.send(can.Message(arbitration_id=0x1, data=b"\x00"))
        time.sleep(0.2)
        frame = receiver.recv(timeout=1.0)
        assert frame is not None
        assert 0.2 <= frame_age(SystemClock().now().timestamp(), frame.timestamp) < 5.0
    finally:
        sender.shutdown()
        receiver.shutdown()
