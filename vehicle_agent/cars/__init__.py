"""The fleet's makes behind one interface; `car_for` picks one from the server's config."""

from __future__ import annotations

from vehicle_agent.cars.base import (
    STALE_PERIODS,
    CarInterface,
    CarReading,
    CarState,
    CruiseButton,
    MessageRule,
)
from vehicle_agent.cars.gm import CadillacXT5
from vehicle_agent.cars.nissan import NissanRogue2018
from vehicle_agent.cars.nissan_canfd import NissanRogue
from vehicle_agent.cars.toyota import ToyotaRav4

# The fleet's cars first: a make and model without a year means the paper's car.
CARS: dict[str, type[CarInterface]] = {
    car.key: car for car in (NissanRogue, CadillacXT5, ToyotaRav4, NissanRogue2018)
}


class UnknownCarError(ValueError):
    """No car interface for this make/model/year; the message lists the known ones."""


def car_for(make: str, model: str | None = None, year: int | None = None) -> CarInterface:
    """The interface for a car key (`nissan_rogue`) or for the config's make, model and year."""
    if make in CARS:
        return CARS[make]()
    for car in CARS.values():
        if car.make.lower() == make.lower() and (
            model is None or car.model.lower() == model.lower()
        ):
            if year is not None and year not in car.years:
                continue
            return car()
    known = ", ".join(f"{c.make} {c.model} {'/'.join(map(str, c.years))}" for c in CARS.values())
    raise UnknownCarError(f"no car interface for {make} {model or ''} {year or ''}; known: {known}")


__all__ = [
    "CARS",
    "STALE_PERIODS",
    "CarInterface",
    "CarReading",
    "CarState",
    "CruiseButton",
    "MessageRule",
    "UnknownCarError",
    "car_for",
]
