"""Operations API: `GET /api/v1/fleet` and `PUT /api/v1/vehicles/{vehicle_id}/assignment`
(docs/interfaces.md), plus `PUT .../maintenance` to take a car out of service.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated

from fastapi import APIRouter, HTTPException, Path, Query, Request

from app.auth import OperatorDep, ViewerDep
from app.core.config import Settings
from app.core.errors import error_responses
from app.core.json_keys import RepeatedKeysRefused
from app.core.sessions import SessionDep
from app.fleet.readiness import Thresholds
from app.fleet.schemas import (
    AssignmentIn,
    AssignmentOut,
    ControllerAssignment,
    FleetOut,
    MaintenanceIn,
    MaintenanceOut,
    counts_out,
    fleet_vehicle_out,
)
from app.fleet.service import (
    PROBLEM_FILTERS,
    AssignmentConflict,
    AssignmentError,
    VehicleNotFound,
    change_assignment,
    count,
    fleet,
    select_entries,
    set_maintenance,
)
from contract.values import StorableText
from contract.vehicles import VEHICLE_ID_PATTERN

router = APIRouter(prefix="/api/v1", tags=["operations"], route_class=RepeatedKeysRefused)

VehicleId = Annotated[str, Path(pattern=VEHICLE_ID_PATTERN)]

ASSIGNMENT_INVALID = (
    "the body breaks its schema (a controller not in the registry, parameters outside their "
    "model): the list of rejected fields"
)
ASSIGNMENT_CONFLICT = (
    "a valid assignment this vehicle cannot take: a lane beyond its corridor's lanes, or a "
    "controller that cannot drive its actuation (the field in the same shape as a 422)"
)


def thresholds(request: Request) -> Thresholds:
    """The readiness thresholds of this server's settings."""
    settings: Settings = request.app.state.settings
    return Thresholds.from_settings(settings)


def _who(principal_token_id: int) -> str:
    return f"token {principal_token_id}"


@router.get("/fleet", responses=error_responses(401, 403, 503))
async def get_fleet(
    request: Request,
    principal: ViewerDep,
    session: SessionDep,
    route: Annotated[StorableText | None, Query(description="Only vehicles on this route.")] = None,
    make: Annotated[StorableText | None, Query(description="Only vehicles of this make.")] = None,
    problem: Annotated[
        str | None,
        Query(
            description="Only vehicles with this problem: " + ", ".join(PROBLEM_FILTERS),
            json_schema_extra={"enum": list(PROBLEM_FILTERS)},
        ),
    ] = None,
) -> FleetOut:
    """Every vehicle with its last ping, last status, readiness checks and verdict (ops token)."""
    if problem is not None and problem not in PROBLEM_FILTERS:
        raise HTTPException(422, f"problem must be one of {', '.join(PROBLEM_FILTERS)}")
    now = datetime.now(UTC)
    entries = await fleet(session, now, thresholds(request))
    chosen = select_entries(entries, route=route, make=make, problem=problem)
    return FleetOut(
        generated_at=now,
        counts=counts_out(count(chosen)),
        vehicles=[fleet_vehicle_out(entry, now) for entry in chosen],
    )


@router.put(
    "/vehicles/{vehicle_id}/assignment",
    responses=error_responses(
        401, 403, 404, 409, 422, 503, described={409: ASSIGNMENT_CONFLICT, 422: ASSIGNMENT_INVALID}
    ),
)
async def put_assignment(
    vehicle_id: VehicleId, body: AssignmentIn, principal: OperatorDep, session: SessionDep
) -> AssignmentOut:
    """Change the lane, route and controller a vehicle drives (operator or admin).

    The car picks the change up the next time it fetches its config. The body's schema is the
    one the agent builds its controller from (contract.controllers): 422 names the field and the
    reason when the body breaks it; 409, in the same shape, when a valid assignment does not fit
    this vehicle (a lane beyond its corridor's, a controller for the other actuation, or a
    `config_version` the vehicle has moved on from).
    """
    try:
        vehicle = await change_assignment(
            session,
            vehicle_id,
            lane=body.lane,
            route=body.route,
            controller_name=body.controller.name,
            controller_params=body.controller.params,
            changed_by=_who(principal.token_id),
            expected_config_version=body.config_version,
        )
    except VehicleNotFound:
        raise HTTPException(404, f"unknown vehicle {vehicle_id}") from None
    except AssignmentError as error:
        raise _field_refused(error) from None
    await session.refresh(vehicle, ["updated_at"])
    return AssignmentOut(
        vehicle_id=vehicle.vehicle_id,
        corridor_id=vehicle.corridor_id,
        lane=vehicle.assigned_lane,
        route=vehicle.route,
        controller=ControllerAssignment(
            name=vehicle.controller_name, params=dict(vehicle.controller_params)
        ),
        config_version=vehicle.config_version,
        updated_at=vehicle.updated_at,
    )


def _field_refused(error: AssignmentError) -> HTTPException:
    """FastAPI's own shape for a rejected field (docs/interfaces.md, "Errors"): 409 for a
    conflict with what the vehicle holds, 422 for a body wrong in itself."""
    where = ["body", *error.field.split(".")]
    status = 409 if isinstance(error, AssignmentConflict) else 422
    return HTTPException(status, [{"loc": where, "msg": error.reason, "type": "value_error"}])


@router.put(
    "/vehicles/{vehicle_id}/maintenance", responses=error_responses(401, 403, 404, 409, 503)
)
async def put_maintenance(
    vehicle_id: VehicleId, body: MaintenanceIn, principal: OperatorDep, session: SessionDep
) -> MaintenanceOut:
    """Take a vehicle out of service for maintenance, or put it back (operator or admin);
    409 when `config_version` is given and the vehicle has moved on from it."""
    try:
        vehicle = await set_maintenance(
            session,
            vehicle_id,
            in_maintenance=body.in_maintenance,
            note=body.note,
            changed_by=_who(principal.token_id),
            expected_config_version=body.config_version,
        )
    except VehicleNotFound:
        raise HTTPException(404, f"unknown vehicle {vehicle_id}") from None
    except AssignmentError as error:
        raise _field_refused(error) from None
    return MaintenanceOut(
        vehicle_id=vehicle.vehicle_id,
        in_maintenance=vehicle.is_in_maintenance,
        note=vehicle.maintenance_note,
        config_version=vehicle.config_version,
    )
