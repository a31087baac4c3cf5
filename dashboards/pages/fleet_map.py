"""The map page: the corridor with every car in its lane (engaged, not engaged, not reporting),
the plan's targets per lane and its buffer regions.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse
from sqlalchemy.ext.asyncio import AsyncSession

from app.core.sessions import SessionDep
from app.fleet.readiness import Thresholds
from app.fleet.service import FleetEntry, fleet
from contract.units import MPH_PER_MPS
from dashboards import data
from dashboards.auth import UserDep
from dashboards.corridor_map import CAR_COLOURS, CarState, MapCar, corridor_map
from dashboards.pages.corridor_choice import chosen_corridor
from dashboards.rendering import page, settings_of

router = APIRouter(include_in_schema=False)


def map_cars(entries: list[FleetEntry], corridor_id: str) -> list[MapCar]:
    """The cars on this corridor with a located last ping, in the map's three states."""
    cars = []
    for entry in entries:
        ping = entry.last_ping
        # drawn where its last ping was matched, on the corridor it was assigned then
        if entry.ping_corridor_id != corridor_id or ping is None or ping.x_m is None:
            continue
        state: CarState
        if entry.readiness.level_of("ping") == "red":
            state = "not reporting"
        elif ping.is_controller_engaged:
            state = "engaged"
        else:
            state = "not engaged"
        cars.append(
            MapCar(
                entry.vehicle.vehicle_id,
                ping.x_m,
                ping.lane or entry.vehicle.assigned_lane,
                state,
                ping.speed_mps,
            )
        )
    return cars


async def _map_context(
    request: Request, session: AsyncSession, corridor_id: str | None
) -> dict[str, Any]:
    now = datetime.now(UTC)
    corridors = await data.corridors(session)
    corridor = chosen_corridor(corridors, corridor_id)
    context: dict[str, Any] = {
        "page": "map",
        "corridors": corridors,
        "corridor": corridor,
        "generated_at": now,
        "refresh_s": settings_of(request).dashboard_refresh_s,
        "map": None,
        "plan": None,
        "plan_age_s": None,
        "states": {},
        "unplaced": 0,
    }
    if corridor is None:
        return context
    plan = await data.latest_plan(session, corridor.corridor_id)
    entries = await fleet(session, now, Thresholds.from_settings(settings_of(request)))
    cars = map_cars(entries, corridor.corridor_id)
    segments = await data.map_segments(session, corridor.corridor_id, plan)
    if segments:
        upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
        context["map"] = corridor_map("corridor-map", segments, corridor.lanes, cars, upper)
    context["plan"] = plan
    if plan is not None and plan.published_at is not None:
        context["plan_age_s"] = (now - plan.published_at).total_seconds()
    context["states"] = {state: sum(car.state == state for car in cars) for state in CAR_COLOURS}
    # The corridor's cars the map cannot draw (no ping yet, or none placed on the corridor):
    # counted, so the map's figures add up to the fleet page's instead of leaving them out.
    drawn = {car.vehicle_id for car in cars}
    context["unplaced"] = sum(
        entry.vehicle.corridor_id == corridor.corridor_id and entry.vehicle.vehicle_id not in drawn
        for entry in entries
    )
    return context


@router.get("/map")
@router.get("/map/live")
async def map_page(
    request: Request, user: UserDep, session: SessionDep, corridor: str | None = None
) -> HTMLResponse:
    """The corridor with every car, the plan's targets per lane and the buffers."""
    context = await _map_context(request, session, corridor)
    return page(request, user, "map", **context)
