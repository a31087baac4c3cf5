"""The agent's threads as `smoothfleet-agent` runs them, in real time for a moment."""

from __future__ import annotations

import logging
import sqlite3
import threading
import time
from pathlib import Path

import can
import pytest

from sim.emulator.car import CarEmulator
from sim.emulator.rig import EmulatorGps, seed_geometry, uniform_plan, vehicle_config
from vehicle_agent.agent import Agent
from vehicle_agent.cars import car_for
from vehicle_agent.clock import SystemClock
from vehicle_agent.engage import EngagePolicy, Mode
from vehicle_agent.runner import run_agent, run_loop
from vehicle_agent.spool import PingSpool


def test_threads_control_the_car_spool_pings_and_stop_cleanly(
    tmp_path: Path, dbc_cache: Path
) -> None:
    clock = SystemClock()
    car_bus = can.Bus(interface="virtual", channel="runner-test")
    agent_bus = can.Bus(interface="virtual", channel="runner-test")
    emulator = CarEmulator(
        "toyota_rav4",
        car_bus,
        speed_mps=25.0,
        position_m=1000.0,
        corridor=seed_geometry(),
        start_s=clock.monotonic(),
        dbc_cache=dbc_cache,
    )
    emulator.driver_engage(set_speed_mph=56)
    agent = Agent(
        vehicle_id="SF-RUN",
        car=car_for("toyota_rav4"),
        bus=agent_bus,
        clock=clock,
        gps=EmulatorGps(emulator, clock),  # type: ignore[arg-type]
        spool=PingSpool(tmp_path / "spool.sqlite"),
        dbc_cache=dbc_cache,
        engage_policy=EngagePolicy(engage_after_s=0.3),
    )
    agent.configure(vehicle_config("toyota_rav4", "microaccel"), seed_geometry())
    agent.accept_plan(uniform_plan(25.0, published=clock.now()))
    stop = threading.Event()

    def car() -> None:
        while not stop.is_set():
            emulator.step(time.monotonic())
            time.sleep(0.005)

    threads = [
        threading.Thread(target=car, daemon=True),
        threading.Thread(target=run_agent, args=(agent, stop), daemon=True),
    ]
    for thread in threads:
        thread.start()
    time.sleep(2.5)
    engaged = agent.state.mode is Mode.ENGAGED
    stop.set()
    for thread in threads:
        thread.join(timeout=20)
    car_bus.shutdown()
    agent_bus.shutdown()
    assert engaged
    assert agent.stats.ticks > 40  # ~30 Hz for 2.5 s, on a busy machine
    assert emulator.agent_frames > 20  # acceleration requests reached the car
    assert agent.state.mode is Mode.STOCK  # handed back on the way out
    with sqlite3.connect(tmp_path / "spool.sqlite") as spool:
        (pings,) = spool.execute("SELECT count(*) FROM ping").fetchone()
    assert pings >= 2


def test_a_step_failing_at_its_loops_rate_is_logged_once_per_interval(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """With the CAN interface down every control pass raised, and each was logged with its
    traceback: 150 in 5 s, about 69 MB an hour on the car's SD card."""
    stop = threading.Event()

    def bus_gone() -> None:
        raise can.CanOperationError("Network is down")

    with caplog.at_level(logging.ERROR, logger="vehicle_agent.runner"):
        thread = threading.Thread(target=run_loop, args=("control", 0.005, bus_gone, stop))
        thread.start()
        time.sleep(0.5)
        stop.set()
        thread.join(timeout=5)

    failures = [record for record in caplog.records if "control step failed" in record.message]
    assert len(failures) == 1
    assert failures[0].exc_info is not None  # with its traceback
