"""An agent driving an emulated car on a virtual CAN bus along the seed corridor, in simulated
time: the bench for the agent's control loop, shared by its tests and bench/agent.py."""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from datetime import UTC, datetime, timedelta
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any

import can

from contract.corridor import CorridorGeometry
from contract.vehicles import ControllerConfig, VehicleConfig
from sim.emulator.car import CarEmulator, board_wired_to
from sim.emulator.leaders import Leader
from vehicle_agent.agent import Agent
from vehicle_agent.cars import car_for
from vehicle_agent.clock import ManualClock
from vehicle_agent.gps import GpsFix
from vehicle_agent.plan import Plan
from vehicle_agent.policies import PolicyStore
from vehicle_agent.ports import ButtonPort
from vehicle_agent.safety import SafetyLayer
from vehicle_agent.server import ServerClient
from vehicle_agent.spool import PingSpool

CORRIDOR = "I-24-WB"
_channels = itertools.count()


@lru_cache(maxsize=1)
def seed_corridor_document() -> dict[str, Any]:
    """The packaged seed corridor, read without the server's code (the bench uses this rig)."""
    document: dict[str, Any] = json.loads(
        resources.files("seed_data").joinpath("i24_wb_corridor.json").read_text()
    )
    return document


@lru_cache(maxsize=1)
def seed_geometry() -> CorridorGeometry:
    document = seed_corridor_document()
    return CorridorGeometry.from_segments(
        CORRIDOR, document["corridor"]["lanes"], document["i24_segments"]
    )


def uniform_plan(
    target_speed_mps: float,
    *,
    plan_id: int = 1,
    published: datetime,
    lanes: tuple[int, ...] = (1, 2, 3, 4),
) -> Plan:
    """A plan with one target speed on every sub-segment of the seed corridor."""
    segments = seed_corridor_document()["i24_segments"]
    lane_body = {
        "x_m": [s["start_x_m"] for s in segments],
        "end_x_m": [s["end_x_m"] for s in segments],
        "target_speed_mps": [target_speed_mps] * len(segments),
        "buffers": [],
    }
    return Plan.model_validate(
        {
            "plan_id": plan_id,
            "corridor": CORRIDOR,
            "published_at": published,
            "valid_until": published + timedelta(minutes=10),
            "lanes": [{"lane": lane, **lane_body} for lane in lanes],
        }
    )


class EmulatorGps:
    """GPS fixes from the emulated car's position; `offset_m` moves them sideways off the road;
    `silent` stops new fixes as a receiver gone quiet does, the last one staying the latest (as
    `vehicle_agent.gps.GpsdSource` keeps it)."""

    def __init__(self, emulator: CarEmulator, clock: ManualClock) -> None:
        self.emulator = emulator
        self.clock = clock
        self.offset_m = 0.0
        self.heading_offset_deg = 0.0
        self.lane: int | None = None
        self.silent = False
        # where set, fixes carry the receiver's time: the agent's wall clock plus this many s
        self.utc_ahead_of_wall_s: float | None = None
        self._latest: GpsFix | None = None

    def latest(self) -> GpsFix | None:
        if not self.silent:
            self._latest = self._fix()
        return self._latest

    def _fix(self) -> GpsFix | None:
        fix = self.emulator.gps_fix(self.clock.monotonic())
        if fix is None:
            return None
        if self.offset_m:
            # ~111 km per degree of latitude: move the fix north by offset_m.
            fix = replace(fix, lat=fix.lat + self.offset_m / 111_000.0)
        if self.heading_offset_deg and fix.heading_deg is not None:
            fix = replace(fix, heading_deg=(fix.heading_deg + self.heading_offset_deg) % 360.0)
        if self.lane is not None:
            fix = replace(fix, lane=self.lane)
        if self.utc_ahead_of_wall_s is not None:
            fix = replace(fix, utc=self.clock.now() + timedelta(seconds=self.utc_ahead_of_wall_s))
        return fix


@dataclass
class Rig:
    clock: ManualClock
    emulator: CarEmulator
    agent: Agent
    gps: EmulatorGps
    car_bus: can.BusABC
    agent_bus: can.BusABC

    def run(self, seconds: float, *, until: Any = None, network: bool = False) -> float:
        """Advance simulated time tick by tick (talking to the server too when `network`);
        stop early when `until()` is true."""
        period = self.agent.command_period_s
        end = self.clock.monotonic() + seconds
        while self.clock.monotonic() < end - 1e-9:
            self.clock.advance(period)
            self.emulator.step(self.clock.monotonic())
            self.agent.tick()
            self.agent.record()
            if network:
                self.agent.network()
            if until is not None and until():
                break
        return self.clock.monotonic()


def vehicle_config(
    key: str, controller: str, params: dict[str, Any] | None = None, **fields: Any
) -> VehicleConfig:
    """The config the server would give a car of `key` running `controller`; `fields` set or
    override any other of its fields (vehicle_id, assigned_lane, stale_plan_after_s, ...)."""
    car = car_for(key)
    defaults: dict[str, Any] = {
        "vehicle_id": "SF-TEST",
        "make": car.make,
        "model": car.model,
        "year": car.years[0],
        "actuation": car.actuation,
        "corridor_id": CORRIDOR,
        "route": "I-24-WB mainline",
        "assigned_lane": 2,
        "controller": ControllerConfig(name=controller, params=params or {}),
    }
    return VehicleConfig(**(defaults | fields))


@contextmanager
def rig(
    key: str,
    tmp_path: Path,
    dbc_cache: Path,
    *,
    controller: str,
    params: dict[str, Any] | None = None,
    speed_mps: float = 22.0,
    position_m: float = 1000.0,
    leader: Leader | None = None,
    target_speed_mps: float | None = 26.8224,
    server: ServerClient | None = None,
    spool: PingSpool | None = None,
    config_fields: dict[str, Any] | None = None,
    start: datetime | None = None,
    vehicle_id: str = "SF-TEST",
    policies: PolicyStore | None = None,
    button_port: Callable[[SafetyLayer], ButtonPort] | None = None,
) -> Iterator[Rig]:
    """An engaged-ready agent and emulated car (the driver has not set ACC yet); `button_port`
    replaces the make's CAN button frames (a GPIO board not wired to the car: the emulated car
    then sees no press). A car that takes no button frames (the 2023 Rogue) gets, by default,
    a board wired to its switches (`board_wired_to`)."""
    channel = f"agent-rig-{next(_channels)}"
    car_bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
    agent_bus = can.Bus(interface="virtual", channel=channel)
    clock = ManualClock(start or datetime.now(UTC).replace(microsecond=0), monotonic_s=100.0)
    emulator = CarEmulator(
        key,
        car_bus,
        speed_mps=speed_mps,
        position_m=position_m,
        leader=leader,
        corridor=seed_geometry(),
        start_s=clock.monotonic(),
        dbc_cache=dbc_cache,
        frame_epoch_s=lambda: clock.now().timestamp(),
    )
    gps = EmulatorGps(emulator, clock)
    agent = Agent(
        vehicle_id=vehicle_id,
        car=car_for(key),
        bus=agent_bus,
        clock=clock,
        gps=gps,
        spool=spool or PingSpool(tmp_path / "spool.sqlite"),
        server=server,
        dbc_cache=dbc_cache,
        policies=policies,
        button_port=button_port or board_wired_to(emulator),
    )
    if server is None:
        agent.configure(
            vehicle_config(key, controller, params, **(config_fields or {})), seed_geometry()
        )
        if target_speed_mps is not None:
            agent.accept_plan(uniform_plan(target_speed_mps, published=clock.now()))
    try:
        yield Rig(clock, emulator, agent, gps, car_bus, agent_bus)
    finally:
        car_bus.shutdown()
        agent_bus.shutdown()
