"""A process driving part of the demo fleet: real agents on emulated cars in simulated traffic.

    python -m sim.fleet.worker SPEC.json SUMMARY.json

Every vehicle of the spec gets its own virtual CAN bus with a car emulator of its make on one
end and the real `vehicle_agent.Agent` on the other, its own ping spool, and its own bearer
token for the server. The cars drive the seed corridor in the demo's traffic (the leader ahead
of each is a human driving at the traffic's speed) and re-enter at the start when they reach
its end. Time is real time: one control step for every car every 0.1 s, the network calls
(config, plan polls, status, ping uploads) on a few threads, as `vehicle_agent.runner` does in
a car. SIGTERM or SIGINT stops the worker: every agent hands its car back to the stock ACC,
uploads what it spooled, and the summary is written.
"""

from __future__ import annotations

import json
import logging
import math
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from types import FrameType
from typing import Any

import can
import httpx
import numpy as np
from pydantic import BaseModel

from contract.corridor import CorridorGeometry
from sim.drives import load_drive
from sim.emulator.car import CarEmulator, board_wired_to
from sim.emulator.rig import uniform_plan, vehicle_config
from sim.energy import RAV4_2019
from sim.fleet.traffic import CorridorTraffic, TrafficLeaders, synthetic_waves
from vehicle_agent.agent import Agent
from vehicle_agent.cars import car_for
from vehicle_agent.clock import ManualClock
from vehicle_agent.engage import Mode
from vehicle_agent.gps import GpsFix
from vehicle_agent.policies import PolicyStore
from vehicle_agent.server import ServerClient, ServerError
from vehicle_agent.spool import PingSpool

log = logging.getLogger("smoothfleet.fleet")

CONTROL_PERIOD_S = 0.1
NETWORK_THREADS = 4
NETWORK_PAUSE_S = 0.2
# The driver sets ACC near the posted limit; the agent moves the setting from there.
DRIVER_SET_SPEED_MPH = 70
# How long a driver takes to resume once the stock ACC holds the car at a standstill (the
# emulated RAV4 and 2023 Rogue hold until then, `sim.emulator.car.HOLDS_STANDSTILL`). No
# recording gives it; without a driver who resumes, a car stopped in a wave would stay there
# for the rest of the run.
DRIVER_RESUME_AFTER_S = 2.0
# Where a car re-enters the corridor after reaching its end (m from either end).
WRAP_MARGIN_M = 60.0
# The leader starts this far ahead: about the stock ACC's widest time gap at the traffic speed.
START_TIME_GAP_S = 2.0
# At most this many ticks of a car per control step: a late step must not grow the next one.
MAX_SUB_TICKS = 4
PROGRESS_STEPS = 20  # about every 2 s


class VehicleSpec(BaseModel):
    """One fleet car: roster identity, lane, token and where it starts."""

    vehicle_id: str
    make: str
    model: str
    year: int
    lane: int
    token: str
    position_m: float


class WorkerSpec(BaseModel):
    """What a worker runs (written by the demo, read here)."""

    server_url: str
    corridor_id: str
    epoch_unix_s: float
    drive_path: str | None
    traffic_offset_s: float
    spool_dir: str
    dbc_cache: str
    vehicles: list[VehicleSpec]
    # Where the worker rewrites its recent control-step timing every PROGRESS_STEPS steps (the
    # demo's status line reads it); None: nowhere.
    progress_path: str | None = None


class EmulatorGps:
    """The emulated car's position as a GPS receiver reports it."""

    def __init__(self, emulator: CarEmulator, clock: ManualClock) -> None:
        self.emulator = emulator
        self.clock = clock

    def latest(self) -> GpsFix | None:
        """A fix for now."""
        return self.emulator.gps_fix(self.clock.monotonic())


@dataclass
class FleetCar:
    """An emulated car, the agent driving it on its own clock, its two ends of the bus."""

    spec: VehicleSpec
    clock: ManualClock
    emulator: CarEmulator
    agent: Agent
    buses: tuple[can.BusABC, can.BusABC]

    def configure_without_server(
        self, controller: str, geometry: CorridorGeometry, plan_speed_mps: float
    ) -> None:
        """Give the agent what the server's config and a plan at `plan_speed_mps` would give it
        (a fleet with no server: bench/fleet_step.py, the tests)."""
        config = vehicle_config(
            self.agent.car.key,
            controller,
            vehicle_id=self.spec.vehicle_id,
            year=self.spec.year,
            assigned_lane=self.spec.lane,
            stale_plan_after_s=3600.0,
        )
        self.agent.configure(config, geometry)
        self.agent.accept_plan(
            uniform_plan(plan_speed_mps, published=self.clock.now(), lanes=(self.spec.lane,))
        )

    @property
    def sub_ticks(self) -> bool:
        """An acceleration-commanding car is ticked at its own command period (the RAV4's
        requests go out at ~30 Hz and the safety layer checks their jerk at that rate)."""
        return self.agent.car.actuation == "accel"


class Fleet:
    """The cars of one worker and the traffic they drive in, stepped together in real time.

    No network here: `server_for` gives each car's agent its server client (None: an agent that
    never talks to a server, configured by the caller, as bench/fleet_step.py does).
    """

    def __init__(
        self,
        vehicles: list[VehicleSpec],
        corridor: CorridorGeometry,
        traffic: CorridorTraffic,
        *,
        epoch_unix_s: float,
        spool_dir: Path,
        dbc_cache: Path,
        server_for: Callable[[VehicleSpec], ServerClient | None],
    ) -> None:
        self.corridor = corridor
        self.epoch_unix_s = epoch_unix_s
        self.lap_m = corridor.length_m - 2 * WRAP_MARGIN_M
        self.traffic = traffic
        starts = np.array([vehicle.position_m for vehicle in vehicles])
        speeds = traffic.speed_mps(self.demo_time_s(), starts)
        self.leaders = TrafficLeaders(
            traffic, starts + START_TIME_GAP_S * speeds + 5.0, self.demo_time_s()
        )
        self.cars = [
            self._car(index, vehicle, float(speed), spool_dir, dbc_cache, server_for(vehicle))
            for index, (vehicle, speed) in enumerate(zip(vehicles, speeds, strict=True))
        ]
        self.steps = 0
        self.engaged_steps = 0
        self.distance_m = 0.0
        self.fuel_g = 0.0
        self.driving_s = 0.0
        self.last_step_s = time.monotonic()

    def demo_time_s(self) -> float:
        """Seconds since the demo started (the traffic's clock)."""
        return time.time() - self.epoch_unix_s

    def _car(
        self,
        index: int,
        vehicle: VehicleSpec,
        speed_mps: float,
        spool_dir: Path,
        dbc_cache: Path,
        server: ServerClient | None,
    ) -> FleetCar:
        car = car_for(vehicle.make, vehicle.model, vehicle.year)
        channel = f"fleet-{vehicle.vehicle_id}"
        car_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        agent_bus = can.Bus(interface="virtual", channel=channel)
        clock = ManualClock(datetime.now(UTC), monotonic_s=time.monotonic())
        now = clock.monotonic()
        emulator = CarEmulator(
            car,
            car_bus,
            speed_mps=speed_mps,
            position_m=vehicle.position_m,
            leader=self.leaders.leader(index),
            corridor=self.corridor,
            lane=vehicle.lane,
            start_s=now,
            dbc_cache=dbc_cache,
            frame_epoch_s=lambda: clock.now().timestamp(),
        )
        emulator.driver_engage(DRIVER_SET_SPEED_MPH)
        emulator.driver.resume_after_s = DRIVER_RESUME_AFTER_S
        agent = Agent(
            vehicle_id=vehicle.vehicle_id,
            car=car,
            bus=agent_bus,
            clock=clock,
            gps=EmulatorGps(emulator, clock),
            # Safe against the worker dying, not a power cut of the host: flushing a hundred
            # spools to one disk every second would block the control loop (vehicle_agent/spool.py).
            spool=PingSpool(spool_dir / f"{vehicle.vehicle_id}.sqlite", power_safe=False),
            server=server,
            dbc_cache=dbc_cache,
            # each car keeps the policies it downloads, as a car in the field does
            policies=PolicyStore(spool_dir / "policies" / vehicle.vehicle_id),
            button_port=board_wired_to(emulator),
        )
        return FleetCar(vehicle, clock, emulator, agent, (car_bus, agent_bus))

    def start(self) -> float:
        """Bring every car to now in one go (through the time it took to build the fleet)."""
        start = time.monotonic()
        for car in self.cars:
            car.clock.set(start)
            car.emulator.step(start)
        self.last_step_s = start
        return start

    def control_step(self) -> None:
        """Advance traffic and cars to now, then every agent's tick and ping."""
        now = time.monotonic()
        dt = now - self.last_step_s
        self.last_step_s = now
        self.leaders.advance(self.demo_time_s())
        speeds = np.empty(len(self.cars))
        accels = np.empty(len(self.cars))
        for index, car in enumerate(self.cars):
            before = car.emulator.position_m
            previous = car.clock.monotonic()
            ticks = 1
            if car.sub_ticks:
                ticks = math.ceil((now - previous) / car.agent.command_period_s - 1e-6)
                ticks = min(max(ticks, 1), MAX_SUB_TICKS)
            for tick in range(1, ticks + 1):
                moment = previous + (now - previous) * tick / ticks
                car.clock.set(moment)
                car.emulator.step(moment)
                try:
                    car.agent.tick()
                except Exception:
                    # as on a car (vehicle_agent.runner): the agent has handed back; its loop,
                    # and every other car of the worker, drive on
                    log.exception("vehicle %s: control step failed", car.spec.vehicle_id)
            car.agent.record()
            self.distance_m += car.emulator.position_m - before
            if car.emulator.position_m > self.corridor.length_m - WRAP_MARGIN_M:
                car.emulator.position_m -= self.lap_m
                self.leaders.wrap(index, self.lap_m)
            speeds[index] = car.emulator.speed_mps
            accels[index] = car.emulator.accel_mps2
            self.engaged_steps += car.agent.state.mode is Mode.ENGAGED
        self.fuel_g += float(RAV4_2019.fuel_rate_gps(speeds, accels).sum()) * dt
        self.driving_s += dt * len(self.cars)
        self.steps += 1

    def close(self) -> tuple[int, int]:
        """Hand every car back, upload what is spooled, close the buses; (spooled, uploaded)."""
        uploaded = spooled = 0
        for car in self.cars:
            car.agent.upload()
            spooled += car.agent.stats.pings_spooled
            uploaded += car.agent.stats.pings_uploaded
            car.agent.shutdown()
            for bus in car.buses:
                bus.shutdown()
        return spooled, uploaded


class Worker:
    """The cars of one spec, stepped together in real time, talking to the server."""

    def __init__(self, spec: WorkerSpec) -> None:
        self.spec = spec
        self.stop = threading.Event()
        self.http = httpx.Client(base_url=spec.server_url, limits=httpx.Limits(max_connections=16))
        drive = load_drive(Path(spec.drive_path)) if spec.drive_path else synthetic_waves()
        self.fleet = Fleet(
            spec.vehicles,
            self._corridor(spec.vehicles[0]),
            CorridorTraffic(drive, start_offset_s=spec.traffic_offset_s),
            epoch_unix_s=spec.epoch_unix_s,
            spool_dir=Path(spec.spool_dir),
            dbc_cache=Path(spec.dbc_cache),
            server_for=lambda vehicle: ServerClient(self.http, vehicle.vehicle_id, vehicle.token),
        )
        self.late_steps = 0
        self.control_cpu_s = 0.0

    def _corridor(self, vehicle: VehicleSpec) -> CorridorGeometry:
        client = ServerClient(self.http, vehicle.vehicle_id, vehicle.token)
        for _ in range(30):
            try:
                return client.corridor(self.spec.corridor_id)
            except ServerError as error:
                log.warning("corridor geometry not available yet: %s", error)
                time.sleep(1.0)
        raise SystemExit(f"fleet worker: no geometry for corridor {self.spec.corridor_id}")

    def control_loop(self) -> None:
        """One control step every CONTROL_PERIOD_S until stopped (late steps are counted)."""
        fleet = self.fleet
        start = fleet.start()
        next_step = time.monotonic()
        window = (fleet.steps, self.late_steps, start)
        while not self.stop.is_set():
            cpu_before = time.thread_time()
            fleet.control_step()
            self.control_cpu_s += time.thread_time() - cpu_before
            next_step += CONTROL_PERIOD_S
            pause = next_step - time.monotonic()
            if pause > 0:
                self.stop.wait(pause)
            else:
                self.late_steps += 1
                next_step = time.monotonic()
            if fleet.steps - window[0] >= PROGRESS_STEPS:
                window = self._write_progress(window)

    def _write_progress(self, window: tuple[int, int, float]) -> tuple[int, int, float]:
        """Rewrite the progress file with the steps since `window`; the next window's start."""
        now = time.monotonic()
        if self.spec.progress_path is not None:
            path = Path(self.spec.progress_path)
            progress = {
                "window_steps": self.fleet.steps - window[0],
                "window_late_steps": self.late_steps - window[1],
                "window_wall_s": now - window[2],
            }
            partial = path.with_suffix(".partial")
            partial.write_text(json.dumps(progress))
            partial.replace(path)  # readers never see half a file
        return self.fleet.steps, self.late_steps, now

    def network_loop(self, cars: list[FleetCar]) -> None:
        """The agents' blocking HTTP calls, each when due."""
        while not self.stop.is_set():
            for car in cars:
                try:
                    car.agent.network()
                except Exception:  # one car's failure must not stop the others
                    log.exception("vehicle %s: network step failed", car.spec.vehicle_id)
            self.stop.wait(NETWORK_PAUSE_S)

    def run(self) -> dict[str, Any]:
        """Drive until stopped; hand back, upload the spools, and summarise."""
        threads = [threading.Thread(target=self.control_loop, name="control", daemon=True)]
        for part in range(NETWORK_THREADS):
            threads.append(
                threading.Thread(
                    target=self.network_loop,
                    args=(self.fleet.cars[part::NETWORK_THREADS],),
                    name=f"network-{part}",
                    daemon=True,
                )
            )
        for thread in threads:
            thread.start()
        self.stop.wait()
        for thread in threads:
            thread.join(timeout=30)
        return self.finish()

    def finish(self) -> dict[str, Any]:
        """Hand every car back, upload what is spooled, close the buses; the summary."""
        fleet = self.fleet
        spooled, uploaded = fleet.close()
        self.http.close()
        cars = max(1, len(fleet.cars))
        return {
            "vehicles": len(fleet.cars),
            "control_steps": fleet.steps,
            "late_steps": self.late_steps,
            "control_cpu_s": self.control_cpu_s,
            "control_wall_s": fleet.driving_s / cars,
            "engaged_share": fleet.engaged_steps / max(1, fleet.steps * cars),
            "pings_spooled": spooled,
            "pings_uploaded": uploaded,
            "distance_m": fleet.distance_m,
            "driving_s": fleet.driving_s,
            "fuel_g": fleet.fuel_g,
        }


def main() -> None:
    """Entry point: `python -m sim.fleet.worker SPEC.json SUMMARY.json`."""
    logging.basicConfig(level=logging.WARNING, format="%(asctime)s %(name)s %(message)s")
    spec_path, summary_path = Path(sys.argv[1]), Path(sys.argv[2])
    worker = Worker(WorkerSpec.model_validate_json(spec_path.read_text()))

    def stop(signum: int, frame: FrameType | None) -> None:
        worker.stop.set()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    summary_path.write_text(json.dumps(worker.run()))


if __name__ == "__main__":
    main()
