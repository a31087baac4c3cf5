"""The agent's threads as `smoothfleet-agent` runs them, in real time for a moment."""

from __future__ import annotations

import logging
import socket
import sqlite3
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import can
import httpx
import pytest

from sim.emulator.car import CarEmulator
from sim.emulator.rig import EmulatorGps, seed_geometry, uniform_plan, vehicle_config
from vehicle_agent.agent import Agent
from vehicle_agent.cars import car_for
from vehicle_agent.clock import SystemClock
from vehicle_agent.engage import EngagePolicy, Mode
from vehicle_agent.runner import LOOP_JOIN_S, run_agent, run_loop
from vehicle_agent.server import ServerClient
from vehicle_agent.spool import PingSpool


@contextmanager
def rav4_agent_running(
    tmp_path: Path, dbc_cache: Path, channel: str, server: ServerClient | None = None
) -> Iterator[tuple[Agent, CarEmulator, threading.Event]]:
    """An emulated RAV4 stepping in real time and its agent run by `run_agent` (its three
    threads), engaged-ready on a uniform plan; the loops stop and are joined on the way out."""
    clock = SystemClock()
    car_bus = can.Bus(interface="virtual", channel=channel)
    agent_bus = can.Bus(interface="virtual", channel=channel)
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
        server=server,
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
    try:
        yield agent, emulator, stop
    finally:
        stop.set()
        for thread in threads:
            thread.join(timeout=30)
        car_bus.shutdown()
        agent_bus.shutdown()


def test_threads_control_the_car_spool_pings_and_stop_cleanly(
    tmp_path: Path, dbc_cache: Path
) -> None:
    with rav4_agent_running(tmp_path, dbc_cache, "runner-test") as (agent, emulator, stop):
        time.sleep(2.5)
        engaged = agent.state.mode is Mode.ENGAGED
        stop.set()
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


class SilentServer:
    """A TCP server that takes connections and never answers: a request to it holds the
    network thread for the whole client timeout. `open` counts connections not yet closed by
    the client."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.url = f"http://127.0.0.1:{self.listener.getsockname()[1]}"
        self.open = 0
        self.accepted = threading.Event()
        threading.Thread(target=self._serve, daemon=True).start()

    def _serve(self) -> None:
        while True:
            try:
                connection, _ = self.listener.accept()
            except OSError:
                return
            self.open += 1
            self.accepted.set()
            threading.Thread(target=self._hold, args=(connection,), daemon=True).start()

    def _hold(self, connection: socket.socket) -> None:
        with connection:
            while connection.recv(4096):  # read the request, answer nothing, until closed
                pass
        self.open -= 1

    def close(self) -> None:
        self.listener.close()


def test_the_car_is_handed_back_before_a_stuck_request_ends(
    tmp_path: Path, dbc_cache: Path
) -> None:
    """The stop joined the network thread (10 s at most) before it handed the car back, and the
    network thread may sit in a request for its whole timeout: the car stayed commanded by a
    stopped agent while systemd's 10 s for the stop ran out. The hand-back now comes as soon as
    the control loop has stopped, while the request is still unanswered."""
    silent = SilentServer()
    http = httpx.Client(base_url=silent.url)
    server = ServerClient(http, "SF-RUN", "token", timeout_s=20.0)
    try:
        with rav4_agent_running(tmp_path, dbc_cache, "runner-stuck", server) as (agent, _, stop):
            deadline = time.monotonic() + 10.0
            while agent.state.mode is not Mode.ENGAGED and time.monotonic() < deadline:
                time.sleep(0.05)
            assert agent.state.mode is Mode.ENGAGED
            assert silent.accepted.wait(timeout=10)  # the network thread is in its first request
            stop.set()
            # the stop may wait for the control and telemetry loops' steps, not for the network
            handed_back_by = time.monotonic() + 2 * LOOP_JOIN_S + 1.0
            while agent.state.mode is not Mode.STOCK and time.monotonic() < handed_back_by:
                time.sleep(0.05)
            assert agent.state.mode is Mode.STOCK
            assert silent.open >= 1  # the request still unanswered (its timeout is 20 s)
    finally:
        silent.close()
        http.close()
