"""The fleet page (piStatus): every vehicle's checks and whether it is cleared for deployment,
filtered by route, make or problem.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse

from app.core.sessions import SessionDep
from app.fleet.readiness import CHECKS, Thresholds, reason_counts
from app.fleet.service import PROBLEM_FILTERS, FleetEntry, count, fleet, select_entries
from dashboards.auth import PageError, UserDep
from dashboards.rendering import page, quote_path, settings_of

router = APIRouter(include_in_schema=False)


def _fleet_filters(
    entries: list[FleetEntry], route: str | None, make: str | None, problem: str | None
) -> dict[str, Any]:
    route = route or None
    make = make or None
    problem = problem or None
    if problem is not None and problem not in PROBLEM_FILTERS:
        raise PageError(400, "Unknown filter", f"There is no problem filter called {problem!r}.")
    chosen = select_entries(entries, route=route, make=make, problem=problem)
    query = "&".join(
        f"{name}={quote_path(value)}"
        for name, value in (("route", route), ("make", make), ("problem", problem))
        if value
    )
    return {
        "entries": chosen,
        "counts": count(chosen),
        "reasons": reason_counts([entry.readiness for entry in chosen]),
        "total": len(entries),
        "routes": sorted({entry.vehicle.route for entry in entries}),
        "makes": sorted({entry.vehicle.make for entry in entries}),
        "problems": PROBLEM_FILTERS,
        "route": route,
        "make": make,
        "problem": problem,
        "query": query,
        "checks": CHECKS,
    }


async def _fleet_context(
    request: Request,
    session: SessionDep,
    route: str | None,
    make: str | None,
    problem: str | None,
) -> dict[str, Any]:
    now = datetime.now(UTC)
    entries = await fleet(session, now, Thresholds.from_settings(settings_of(request)))
    context = _fleet_filters(entries, route, make, problem)
    context["generated_at"] = now
    context["refresh_s"] = settings_of(request).dashboard_refresh_s
    context["hold_s"] = settings_of(request).readiness_hold_s
    return context


@router.get("/fleet")
@router.get("/fleet/live")
async def fleet_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    route: str | None = None,
    make: str | None = None,
    problem: str | None = None,
) -> HTMLResponse:
    """piStatus: every vehicle's checks and whether it is cleared for deployment."""
    context = await _fleet_context(request, session, route, make, problem)
    return page(request, user, "fleet", page="fleet", **context)
