"""Plans for vehicles and analysts: the latest valid plan (ETag/304, 503 + Retry-After when
there is none), a vehicle's lane plan, and the planner's run history.

Who may read: any ops token; a vehicle token the plans of its own vehicle's corridor (and its own
vehicle's plan); a feed token nothing here.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Annotated, Any, Literal

from fastapi import APIRouter, HTTPException, Path, Query, Request, Response
from pydantic import BeforeValidator

from app.auth import AuthDep, Principal
from app.core.config import Settings
from app.core.errors import error_responses, is_database_outage, service_unavailable
from app.core.sessions import SessionDep
from app.plans.schemas import PlanHistoryOut
from app.plans.service import (
    HeldPlans,
    PlanDocuments,
    corridor_lanes,
    latest_valid_plan,
    plan_document,
    plan_history,
    vehicle_assignment,
)
from contract.errors import NO_VALID_PLAN
from contract.plans import PlanOut
from contract.values import StorableText, time_text
from contract.vehicles import CONFIG_VERSION_HEADER, VEHICLE_ID_PATTERN

router = APIRouter(prefix="/api/v1", tags=["plans"])

PLAN_RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"model": PlanOut, "description": "the plan"},
    304: {"description": "unchanged since If-None-Match"},
    **error_responses(401, 403, 404, 422, 503),
}


async def _readable_corridor(
    principal: Principal, session: SessionDep, corridor_id: str | None
) -> str | None:
    """The corridor a caller may read plans of (a vehicle: only its own)."""
    if principal.role == "feed":
        raise HTTPException(403, "a feed token may not read plans")
    if principal.role != "vehicle":
        return corridor_id
    assignment = await vehicle_assignment(session, principal.vehicle_id or "")
    if assignment is None:
        raise HTTPException(403, "this vehicle token's vehicle is no longer on the roster")
    own = assignment.corridor_id
    if corridor_id is not None and corridor_id != own:
        raise HTTPException(403, f"a vehicle token may read only its own corridor's plans ({own})")
    return own


def _documents(request: Request) -> PlanDocuments:
    """This application's cache of rendered plan documents (made by create_api)."""
    documents: PlanDocuments = request.app.state.plan_documents
    return documents


def _matches(if_none_match: str | None, etag: str) -> bool:
    if not if_none_match:
        return False
    candidates = {tag.strip().removeprefix("W/") for tag in if_none_match.split(",")}
    return "*" in candidates or etag in candidates


def _held(request: Request) -> HeldPlans:
    """This application's memory of what it last served (made by create_api)."""
    held: HeldPlans = request.app.state.held_plans
    return held


async def _serve_latest(
    request: Request, session: SessionDep, corridor_id: str, lane: int | None
) -> Response:
    held = _held(request)
    now = datetime.now(UTC)
    plan_id: int | None = None
    try:
        lanes = await corridor_lanes(session, corridor_id)
        if lanes is not None:
            held.lanes[corridor_id] = lanes
            latest = await latest_valid_plan(session, corridor_id, now)
            if latest is None:
                held.plans.pop(corridor_id, None)
            else:
                held.plans[corridor_id] = latest
                plan_id = latest[0]
    except Exception as error:
        if not is_database_outage(error) or corridor_id not in held.lanes:
            raise
        # the database is away: what was read last still holds until its valid_until
        lanes, plan_id = held.lanes[corridor_id], held.valid_plan_id(corridor_id, now)
        if plan_id is None or _documents(request).get(plan_id, lane) is None:
            raise
    if lanes is None:
        raise HTTPException(404, f"unknown corridor {corridor_id}")
    if lane is not None and not 1 <= lane <= lanes:
        # A lane the corridor does not have has no plan: not found, as an unknown corridor.
        raise HTTPException(404, f"no lane {lane} on {corridor_id} (lanes 1-{lanes})")
    settings: Settings = request.app.state.settings
    if plan_id is None:
        return service_unavailable(
            f"no valid plan for {corridor_id}: leave the car to its stock ACC",
            retry_after_s=max(1, round(settings.planner_period_s)),
            code=NO_VALID_PLAN,
        )
    etag = f'"plan-{plan_id}-lane-{lane if lane is not None else "all"}"'
    headers = {"ETag": etag, "Cache-Control": "no-cache"}
    if _matches(request.headers.get("if-none-match"), etag):
        return Response(status_code=304, headers=headers)
    body = await plan_document(session, _documents(request), corridor_id, plan_id, lane)
    return Response(body, media_type="application/json", headers=headers)


@router.get("/plans/latest", responses=PLAN_RESPONSES, response_model=PlanOut)
async def get_latest_plan(
    request: Request,
    principal: AuthDep,
    session: SessionDep,
    corridor: Annotated[StorableText, Query(description="corridor id, e.g. I-24-WB")],
    lane: Annotated[int | None, Query(description="one lane only (1 = leftmost)")] = None,
) -> Response:
    """The newest published plan still valid, all lanes or one; 503 + Retry-After if none."""
    readable = await _readable_corridor(principal, session, corridor)
    return await _serve_latest(request, session, readable or corridor, lane)


_CONFIG_VERSION = {
    CONFIG_VERSION_HEADER: {
        "description": "the vehicle's config_version now (a car running another fetches its "
        "config)",
        "schema": {"type": "integer"},
    }
}
VEHICLE_PLAN_RESPONSES: dict[int | str, dict[str, Any]] = {
    **PLAN_RESPONSES,
    200: {**PLAN_RESPONSES[200], "headers": _CONFIG_VERSION},
    304: {**PLAN_RESPONSES[304], "headers": _CONFIG_VERSION},
    404: {**PLAN_RESPONSES[404], "headers": _CONFIG_VERSION},
    503: {**PLAN_RESPONSES[503], "headers": _CONFIG_VERSION},
}


@router.get("/vehicles/{vehicle_id}/plan", responses=VEHICLE_PLAN_RESPONSES, response_model=PlanOut)
async def get_vehicle_plan(
    vehicle_id: Annotated[str, Path(pattern=VEHICLE_ID_PATTERN)],
    request: Request,
    principal: AuthDep,
    session: SessionDep,
    lane: Annotated[
        int | None,
        Query(description="the lane of the config the car runs (default: its assigned lane)"),
    ] = None,
) -> Response:
    """The latest valid plan of the vehicle's corridor for one lane: the lane the car asks for
    (the one of the config it has applied), else its assigned lane."""
    if principal.role == "feed" or (
        principal.role == "vehicle" and principal.vehicle_id != vehicle_id
    ):
        raise HTTPException(
            403, f"{principal.token_words} may not read the plan of vehicle {vehicle_id}"
        )
    held = _held(request)
    try:
        assignment = await vehicle_assignment(session, vehicle_id)
    except Exception as error:
        if not is_database_outage(error) or vehicle_id not in held.assignments:
            raise
        assignment = held.assignments[vehicle_id]
    if assignment is None:
        raise HTTPException(404, f"unknown vehicle {vehicle_id}")
    held.assignments[vehicle_id] = assignment
    # Every answer a car gets to its plan poll once its vehicle is known (a plan, 304, no valid
    # plan, no such lane) names the version of its config now: a car running another version
    # fetches its config at once, so an operator who pulls a car (active false, maintenance) or
    # reassigns it reaches it within a plan poll rather than at its next full config refresh
    # (60 s). The 404 matters most: a car moved to a corridor without the lane it polls gets
    # nothing else until that refresh.
    version = {CONFIG_VERSION_HEADER: str(assignment.config_version)}
    try:
        answer = await _serve_latest(
            request,
            session,
            assignment.corridor_id,
            assignment.assigned_lane if lane is None else lane,
        )
    except HTTPException as refusal:
        refusal.headers = {**(refusal.headers or {}), **version}
        raise
    answer.headers.update(version)
    return answer


@router.get("/plans", responses=error_responses(401, 403, 404, 503))
async def get_plan_history(
    principal: AuthDep,
    session: SessionDep,
    corridor: Annotated[
        StorableText | None, Query(description="corridor id (all when omitted)")
    ] = None,
    since: Annotated[
        datetime | None, BeforeValidator(time_text), Query(description="runs started at or after")
    ] = None,
    until: Annotated[
        datetime | None, BeforeValidator(time_text), Query(description="runs started before")
    ] = None,
    status: Annotated[Literal["published", "skipped", "failed"] | None, Query()] = None,
    limit: Annotated[int, Query(ge=1, le=1000)] = 100,
) -> PlanHistoryOut:
    """Planner runs with their algorithm, parameters and inputs, newest first (for replay).

    An unknown corridor is a 404, as on `plans/latest`: an empty history would read as a
    corridor the planner never ran for, and hide a misspelt id. So is `until` before `since` a
    422, not an empty list: the window is [since, until)."""
    corridor_id = await _readable_corridor(principal, session, corridor)
    for name, moment in (("since", since), ("until", until)):
        if moment is not None and moment.tzinfo is None:
            raise HTTPException(422, f"{name} needs a time zone (RFC 3339)")
    if since is not None and until is not None and until < since:
        # an empty answer would read as no planner run in a window the caller did not mean
        raise HTTPException(
            422, f"until ({until.isoformat()}) is before since ({since.isoformat()})"
        )
    if corridor_id is not None and await corridor_lanes(session, corridor_id) is None:
        raise HTTPException(404, f"unknown corridor {corridor_id}")
    # one more than asked for tells whether the window held more (the answer said nothing, and
    # a window of more than `limit` planner cycles read as complete)
    runs = await plan_history(session, corridor_id, since, until, status, limit + 1)
    if len(runs) <= limit:
        return PlanHistoryOut(plans=runs, truncated=False)
    # The next page is asked with `until` = the oldest run's start, and the window ends before
    # `until`: runs started at the same instant as the first one cut off (the corridors of one
    # cycle) are left to that page whole, unless the page would keep none.
    cut_at = runs[limit].started_at
    page = [run for run in runs[:limit] if run.started_at != cut_at] or runs[:limit]
    return PlanHistoryOut(plans=page, truncated=True)
