"""The demo fleet's control step: one car's failed pass does not stop the others."""

from __future__ import annotations

import time
from pathlib import Path

import can
import numpy as np
import pytest

from sim.drives import drive_from_speeds
from sim.emulator.rig import seed_geometry
from sim.fleet.traffic import CorridorTraffic
from sim.fleet.worker import CONTROL_PERIOD_S, Fleet, FleetCar, VehicleSpec
from vehicle_agent.engage import Mode

# Two cars of the roster's makes, far apart on the seed corridor, with their controllers.
CARS = [
    (VehicleSpec(vehicle_id="SF-001", make="Nissan", model="Rogue", year=2023, lane=1,
                 token="", position_m=500.0), "microaccel_acc"),
    (VehicleSpec(vehicle_id="SF-098", make="Toyota", model="RAV4", year=2020, lane=1,
                 token="", position_m=3000.0), "rl_accel"),
]  # fmt: skip


def drive(fleet: Fleet, seconds: float) -> None:
    """Control steps in real time, as the worker's control thread runs them."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        fleet.control_step()
        time.sleep(CONTROL_PERIOD_S)


def engaged(car: FleetCar) -> bool:
    return car.agent.state.mode is Mode.ENGAGED


def test_one_cars_failed_pass_hands_it_back_and_the_others_drive_on(
    tmp_path: Path, dbc_cache: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    fleet = Fleet(
        [spec for spec, _ in CARS],
        seed_geometry(),
        CorridorTraffic(drive_from_speeds("steady", np.full(6001, 25.0))),
        epoch_unix_s=time.time(),
        spool_dir=tmp_path,
        dbc_cache=dbc_cache,
        server_for=lambda vehicle: None,
    )
    try:
        for car, (_, controller) in zip(fleet.cars, CARS, strict=True):
            car.configure_without_server(controller, seed_geometry(), 25.0)
        fleet.start()
        drive(fleet, 3.0)
        assert all(engaged(car) for car in fleet.cars), [c.agent.state.reason for c in fleet.cars]
        failing, other = fleet.cars

        def network_down(timeout: float | None = None) -> None:
            raise can.CanOperationError("Network is down")

        monkeypatch.setattr(failing.buses[1], "recv", network_down)
        steps = fleet.steps
        drive(fleet, 1.0)  # no exception leaves the step
        assert fleet.steps > steps
        assert failing.agent.state.reason == "agent step failed"
        assert not engaged(failing)
        assert engaged(other)
    finally:
        fleet.close()
