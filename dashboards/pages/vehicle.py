"""One vehicle's page: its checks, its speed against its plan's target, its status reports and
engagement per day; operators change its assignment or take it out of service here.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta
from typing import Annotated, Any
from zoneinfo import ZoneInfo

from fastapi import APIRouter, Form, Request
from fastapi import Path as PathParameter
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.concurrency import run_in_threadpool

from app.core.sessions import SessionDep
from app.fleet.readiness import CHECKS, Thresholds
from app.fleet.service import (
    AssignmentError,
    FleetEntry,
    VehicleNotFound,
    change_assignment,
    set_maintenance,
    vehicle_entry,
)
from app.vehicles.schemas import CONTROLLER_ACTUATIONS
from contract.units import MPH_PER_MPS
from contract.vehicles import VEHICLE_ID_PATTERN
from dashboards import data
from dashboards.auth import PageError, UserDep, check_form
from dashboards.charts import Axis, Band, Series, chart, line_figure
from dashboards.pages.analytics import ANALYTICS_DAYS, engagement_chart, local_days_ago
from dashboards.rendering import display_zone, figure_refresh_s, render, settings_of

router = APIRouter(include_in_schema=False)

# The vehicle id is checked as the API checks it, before any query: one the roster cannot hold
# (a NUL, which PostgreSQL text refuses) was refused by the database instead, and its refusal
# reached a browser as the API's JSON 422, not a page.
VehicleId = Annotated[str, PathParameter(pattern=VEHICLE_ID_PATTERN)]
TRACE_WINDOW = timedelta(minutes=30)


async def _entry_or_404(request: Request, session: SessionDep, vehicle_id: str) -> FleetEntry:
    try:
        return await vehicle_entry(
            session,
            vehicle_id,
            datetime.now(UTC),
            Thresholds.from_settings(settings_of(request)),
        )
    except VehicleNotFound:
        raise PageError(
            404,
            "Unknown vehicle",
            f"There is no vehicle {vehicle_id} in the roster. Check the id on the fleet page, or "
            "add the car with `smoothfleet vehicles add`.",
        ) from None


def _speed_chart(entry: FleetEntry, trace: data.Trace, zone: ZoneInfo) -> Any:
    times = [moment.timestamp() for moment in trace.ts]
    bands = []
    start: float | None = None
    for moment, engaged in zip(times, trace.engaged, strict=True):
        if engaged and start is None:
            start = moment
        if not engaged and start is not None:
            bands.append(Band(start, moment, "#bbf7d0"))
            start = None
    if start is not None:
        bands.append(Band(start, times[-1] + 1.0, "#bbf7d0"))
    return chart(
        "vehicle-speed",
        line_figure(
            f"Speed of {entry.vehicle.vehicle_id} against its plan's target",
            [
                Series("speed", times, [v * MPH_PER_MPS for v in trace.speed_mps], "#2563eb"),
                Series(
                    "plan target",
                    times,
                    [None if v is None else v * MPH_PER_MPS for v in trace.target_mps],
                    "#dc2626",
                    style="step",
                    dashed=True,
                ),
            ],
            Axis("time", "time"),
            Axis("speed (mph)", lower=0.0),
            bands=bands,
            band_label="controller engaged",
            zone=zone,
        ),
    )


async def _vehicle_history(
    request: Request, session: AsyncSession, entry: FleetEntry
) -> dict[str, Any]:
    """The car's recent past: speed against its plan, engagement per local day, its reports."""
    vehicle_id = entry.vehicle.vehicle_id
    now = datetime.now(UTC)
    zone = display_zone(settings_of(request))
    context: dict[str, Any] = {
        "entry": entry,
        "history_generated_at": now,
        "history_refresh_s": figure_refresh_s(request),
        "zone_name": zone.key,
        "speed_chart": None,
        "engagement_chart": None,
    }
    if entry.last_ping is not None:
        trace = await data.vehicle_trace(session, vehicle_id, entry.last_ping.ts, TRACE_WINDOW)
        if trace.ts:
            context["speed_chart"] = await run_in_threadpool(_speed_chart, entry, trace, zone)
    context["statuses"] = await data.status_history(session, vehicle_id)
    engagement = await data.engagement_per_day(
        session, local_days_ago(now, zone, ANALYTICS_DAYS), zone, vehicle_id=vehicle_id
    )
    context["engagement"] = engagement
    if engagement:
        context["engagement_chart"] = await run_in_threadpool(
            engagement_chart,
            "vehicle-engagement",
            f"Engagement of {vehicle_id} per day",
            engagement,
            zone,
        )
    return context


async def _live_context(session: AsyncSession, entry: FleetEntry) -> dict[str, Any]:
    """What the refreshed top of the page shows: the car's assignment and maintenance (who
    changed them, when), its verdict and checks."""
    vehicle_id = entry.vehicle.vehicle_id
    return {
        "entry": entry,
        "generated_at": datetime.now(UTC),
        "changes": await data.vehicle_changes(session, vehicle_id),
        "out_of_service_since": (
            await data.out_of_service_since(session, vehicle_id)
            if entry.vehicle.is_in_maintenance
            else None
        ),
    }


async def _vehicle_context(
    request: Request, session: SessionDep, vehicle_id: str
) -> dict[str, Any]:
    entry = await _entry_or_404(request, session, vehicle_id)
    return {
        **await _live_context(session, entry),
        "refresh_s": settings_of(request).dashboard_refresh_s,
        "checks": CHECKS,
        "lanes": list(range(1, entry.corridor_lanes + 1)),
        "controllers": sorted(
            name
            for name, actuations in CONTROLLER_ACTUATIONS.items()
            if entry.vehicle.actuation in actuations
        ),
        "params_json": json.dumps(entry.vehicle.controller_params),
        **await _vehicle_history(request, session, entry),
    }


@router.get("/vehicles/{vehicle_id}")
async def vehicle_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    vehicle_id: VehicleId,
    saved: str | None = None,
) -> HTMLResponse:
    """One vehicle: checks, speed against the plan, status history, engagement, assignment."""
    context = await _vehicle_context(request, session, vehicle_id)
    saved_message = {"assignment": "Assignment saved.", "maintenance": "Maintenance saved."}
    return render(
        request,
        "vehicle.html",
        user,
        page="fleet",
        saved=saved_message.get(saved or ""),
        error=None,
        **context,
    )


@router.get("/vehicles/{vehicle_id}/live")
async def vehicle_live(
    request: Request, user: UserDep, session: SessionDep, vehicle_id: VehicleId
) -> HTMLResponse:
    """The vehicle's assignment, maintenance, verdict and checks, for the page's periodic
    refresh (the assignment too: another operator may change it while the page is open)."""
    entry = await _entry_or_404(request, session, vehicle_id)
    return render(request, "_vehicle_live.html", user, **await _live_context(session, entry))


@router.get("/vehicles/{vehicle_id}/history/live")
async def vehicle_history_live(
    request: Request, user: UserDep, session: SessionDep, vehicle_id: VehicleId
) -> HTMLResponse:
    """The vehicle's speed chart, engagement and status reports, for their periodic refresh."""
    entry = await _entry_or_404(request, session, vehicle_id)
    context = await _vehicle_history(request, session, entry)
    return render(request, "_vehicle_history_live.html", user, **context)


async def _not_saved(
    request: Request,
    session: SessionDep,
    user: UserDep,
    vehicle_id: str,
    error: AssignmentError,
    **shown: Any,
) -> Response:
    """The car's page again (422), saying what was not saved and why, beside its field;
    `shown` overrides what the page would show from the database."""
    context = await _vehicle_context(request, session, vehicle_id)
    return render(
        request,
        "vehicle.html",
        user,
        status_code=422,
        page="fleet",
        saved=None,
        error=f"Not saved: {error}",
        field_error=error,
        **{**context, **shown},
    )


MAX_CONFIG_VERSION_DIGITS = 18


def _config_version_read(config_version: str) -> int | None:
    """The config version the form was filled in against (its hidden field); none from a
    client that sends none, which saves without the check, as the API does."""
    if not config_version:
        return None
    # Python reads no integer of over 4,300 digits (a ValueError, which was a 500); a config
    # version is a count of saves, far below 19 digits
    if not (
        config_version.isascii()
        and config_version.isdigit()
        and len(config_version) <= MAX_CONFIG_VERSION_DIGITS
    ):
        raise AssignmentError("config_version", f"{config_version[:40]!r} is not a config version")
    return int(config_version)


def _controller_params_read(params: str) -> dict[str, Any]:
    """The controller's parameters typed into the form, a JSON object."""
    try:
        controller_params = json.loads(params or "{}")
    except json.JSONDecodeError as error:
        raise AssignmentError("controller.params", f"not valid JSON ({error.msg})") from None
    except RecursionError:  # "[" * 100000: deeper than the parser goes (it was a 500)
        raise AssignmentError("controller.params", "nested too deeply") from None
    if not isinstance(controller_params, dict):
        raise AssignmentError("controller.params", "must be a JSON object")
    return controller_params


@router.post("/vehicles/{vehicle_id}/assignment")
async def vehicle_assignment(
    request: Request,
    user: UserDep,
    session: SessionDep,
    vehicle_id: VehicleId,
    lane: Annotated[str, Form()] = "",
    route: Annotated[str, Form()] = "",
    controller: Annotated[str, Form()] = "",
    params: Annotated[str, Form()] = "{}",
    config_version: Annotated[str, Form()] = "",
    csrf_token: Annotated[str, Form()] = "",
) -> Response:
    """Change the vehicle's lane, route and controller (operators and admins)."""
    check_form(user, csrf_token, needs_operator=True)
    await _entry_or_404(request, session, vehicle_id)
    try:
        try:
            lane_number = int(lane)
        except ValueError:
            raise AssignmentError("lane", f"{lane[:40]!r} is not a lane number") from None
        controller_params = _controller_params_read(params)
        read_version = _config_version_read(config_version)
        await change_assignment(
            session,
            vehicle_id,
            lane=lane_number,
            route=route,
            controller_name=controller,
            controller_params=controller_params,
            changed_by=f"dashboard user {user.username}",
            expected_config_version=read_version,
        )
    except AssignmentError as error:
        # the form again as the operator filled it in, not as stored: fixing one field must
        # not silently put the others back. It keeps the version the operator read, too, so
        # a change someone else saved meanwhile is still a conflict when the fix is sent;
        # only the conflict itself hands over the new version, to save again against.
        shown: dict[str, Any] = {}
        if error.field != "config_version":
            shown["config_version_read"] = config_version
        return await _not_saved(
            request,
            session,
            user,
            vehicle_id,
            error,
            params_json=params,
            form={"lane": lane, "route": route, "controller": controller},
            **shown,
        )
    return RedirectResponse(f"/vehicles/{vehicle_id}?saved=assignment", status_code=303)


@router.post("/vehicles/{vehicle_id}/maintenance")
async def vehicle_maintenance(
    request: Request,
    user: UserDep,
    session: SessionDep,
    vehicle_id: VehicleId,
    in_maintenance: Annotated[str, Form()] = "",
    note: Annotated[str, Form()] = "",
    config_version: Annotated[str, Form()] = "",
    csrf_token: Annotated[str, Form()] = "",
) -> Response:
    """Take the vehicle out of service or put it back (operators and admins); a page read
    before someone else changed the car saves nothing (its checkbox would undo their change)."""
    check_form(user, csrf_token, needs_operator=True)
    await _entry_or_404(request, session, vehicle_id)
    ticked = in_maintenance in ("on", "true", "1")
    try:
        await set_maintenance(
            session,
            vehicle_id,
            in_maintenance=ticked,
            note=note,
            changed_by=f"dashboard user {user.username}",
            expected_config_version=_config_version_read(config_version),
        )
    except AssignmentError as error:
        # the form as the operator filled it in: a refusal (a change someone saved meanwhile)
        # must not throw away the note they typed
        return await _not_saved(
            request,
            session,
            user,
            vehicle_id,
            error,
            maintenance_form={"in_maintenance": ticked, "note": note},
        )
    return RedirectResponse(f"/vehicles/{vehicle_id}?saved=maintenance", status_code=303)
