"""The dashboard's pages: login, fleet health (piStatus), map, time-space, vehicle, plans,
feeds, analytics, and the error pages.

Pages are rendered on the server (Jinja2) with their charts drawn by matplotlib (PNG inside the
page); the fleet, map and time-space pages refresh their live part from `.../live` without
reloading. Speeds are shown in mph and places in postmiles (people's units on US roads); times in
the corridor's local time (`dashboard_timezone`).
"""

from __future__ import annotations

import inspect
import json
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Annotated, Any, Literal
from zoneinfo import ZoneInfo

import numpy as np
from fastapi import APIRouter, FastAPI, Form, Query, Request
from fastapi import Path as PathParameter
from fastapi.exceptions import RequestValidationError
from fastapi.responses import (
    HTMLResponse,
    JSONResponse,
    PlainTextResponse,
    RedirectResponse,
    Response,
)
from fastapi.staticfiles import StaticFiles
from fastapi.templating import Jinja2Templates
from jinja2 import pass_context
from jinja2.runtime import Context
from sqlalchemy import RowMapping
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.concurrency import run_in_threadpool
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.core.config import Settings
from app.core.ratelimit import RateLimiter, retry_after_header
from app.core.sessions import SessionDep
from app.fleet.readiness import CHECKS, Thresholds, describe_age, reason_counts
from app.fleet.service import (
    PROBLEM_FILTERS,
    AssignmentError,
    FleetEntry,
    VehicleNotFound,
    change_assignment,
    count,
    fleet,
    select_entries,
    set_maintenance,
    vehicle_entry,
)
from app.models import Corridor, PlanRun
from app.users.service import log_in
from app.vehicles.schemas import CONTROLLER_ACTUATIONS
from contract.units import METRES_PER_MILE, MPH_PER_MPS
from contract.vehicles import VEHICLE_ID_PATTERN
from dashboards import data, motion
from dashboards.auth import (
    LoginRequired,
    PageError,
    PageUser,
    UserDep,
    check_form,
    check_login_csrf,
    clear_session,
    login_csrf_token,
    navigating_user,
    remember_login_csrf,
    safe_next,
    set_session,
)
from dashboards.charts import (
    AMOUNT_STOPS,
    Axis,
    Band,
    ColourScale,
    Series,
    bar_figure,
    chart,
    heatmap_figure,
    line_figure,
)
from dashboards.corridor_map import CAR_COLOURS, CarState, MapCar, corridor_map
from dashboards.figures import time_space

HERE = Path(__file__).parent
log = logging.getLogger(__name__)
templates = Jinja2Templates(directory=HERE / "templates")
router = APIRouter(include_in_schema=False)

# Path parameters are checked as the API checks them, before any query: a vehicle id the roster
# cannot hold (a NUL, which PostgreSQL text refuses) or a plan id beyond bigint was refused by
# the database instead, and its refusal reached a browser as the API's JSON 422, not a page.
VehicleId = Annotated[str, PathParameter(pattern=VEHICLE_ID_PATTERN)]
PlanId = Annotated[int, PathParameter(ge=1, le=2**63 - 1)]  # plan_run.plan_id: bigint identity

TRACE_WINDOW = timedelta(minutes=30)
PLAN_HISTORY = timedelta(minutes=60)
ANALYTICS_DAYS = 30
ADHERENCE_DAYS = 7  # every ping looked up in its plan: a week is the page's budget
ANALYTICS_REFRESH_S = 60.0  # the analytics page's figures are recomputed at most this often
# Parts of pages drawn with matplotlib refresh at most this often (s): a figure costs ~0.1 s of
# the server's CPU, and what they show changes by the minute (plans, INRIX) or slowly.
FIGURE_MIN_REFRESH_S = 15.0
HEATMAP_COLUMNS = 240
HEATMAP_ROWS = 180


def _mph(value: float | None) -> str:
    return "—" if value is None else f"{value * MPH_PER_MPS:.1f}"


def display_zone(settings: Settings) -> ZoneInfo:
    """The time zone people read times in (the corridor's)."""
    return ZoneInfo(settings.dashboard_timezone)


@pass_context
def _localtime(context: Context, value: datetime | None) -> str:
    if value is None:
        return "—"
    zone = display_zone(context["request"].app.state.settings)
    return value.astimezone(zone).strftime("%Y-%m-%d %H:%M:%S %Z")


templates.env.filters["mph"] = _mph
templates.env.filters["localtime"] = _localtime
templates.env.filters["age"] = describe_age


def _settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def _render(
    request: Request,
    name: str,
    user: PageUser | None,
    status_code: int = 200,
    **context: Any,
) -> HTMLResponse:
    return templates.TemplateResponse(
        request,
        name,
        {"user": user, "now": datetime.now(UTC), **context},
        status_code=status_code,
    )


def _figure_refresh_s(request: Request) -> float:
    """How often a part of a page drawn with matplotlib refreshes itself."""
    return max(_settings(request).dashboard_refresh_s, FIGURE_MIN_REFRESH_S)


def _page(request: Request, user: PageUser, name: str, **context: Any) -> HTMLResponse:
    """Page `name`, or at its `/live` path only the part that refreshes itself (the page polls
    it; static/dashboard.js): one handler and one context serve both."""
    if request.url.path.endswith("/live"):
        return _render(request, f"_{name}_live.html", user, **context)
    return _render(request, f"{name}.html", user, **context)


def install(app: FastAPI) -> None:
    """Mount the pages, their static files and their error pages on the app."""
    app.include_router(router)
    app.include_router(motion.router)
    app.mount("/static", StaticFiles(directory=HERE / "static"), name="static")

    async def on_login_required(request: Request, error: Exception) -> Response:
        assert isinstance(error, LoginRequired)
        if request.headers.get("x-requested-with") == "fetch":
            return JSONResponse({"detail": "log in again"}, status_code=401)
        return RedirectResponse(f"/login?next={_quote(error.next_path)}", status_code=303)

    async def on_page_error(request: Request, error: Exception) -> Response:
        assert isinstance(error, PageError)
        return _render(
            request,
            "error.html",
            navigating_user(request),
            status_code=error.status_code,
            title=error.title,
            message=error.message,
            path=request.url.path,
        )

    api_http_error = app.exception_handlers[StarletteHTTPException]

    async def on_http_error(request: Request, error: Exception) -> Response:
        assert isinstance(error, StarletteHTTPException)
        if not wants_page(request):
            answer = api_http_error(request, error)
            return await answer if inspect.isawaitable(answer) else answer
        title, message = ERROR_PAGES.get(error.status_code, ("Error", str(error.detail)))
        return _render(
            request,
            "error.html",
            navigating_user(request),
            status_code=error.status_code,
            title=title,
            message=message,
            path=request.url.path,
        )

    api_invalid_request = app.exception_handlers[RequestValidationError]

    async def on_invalid_request(request: Request, error: Exception) -> Response:
        """A page asked for with a parameter it refuses (`/timespace?hours=100`): the page says
        which and why, as the API's 422 does for its clients."""
        assert isinstance(error, RequestValidationError)
        if not wants_page(request):
            answer = api_invalid_request(request, error)
            return await answer if inspect.isawaitable(answer) else answer
        return _render(
            request,
            "error.html",
            navigating_user(request),
            status_code=422,
            title="Not a valid address",
            message="This page cannot show that: "
            + "; ".join(f"{_field_of(item)}: {item['msg']}" for item in error.errors())
            + ".",
            path=request.url.path,
        )

    async def on_server_error(request: Request, error: Exception) -> Response:
        log.error("page %s failed", request.url.path, exc_info=error)
        if not wants_page(request):
            return PlainTextResponse("Internal Server Error", status_code=500)
        return _render(
            request,
            "error.html",
            navigating_user(request),
            status_code=500,
            title="Something went wrong",
            message="The server failed to show this page; the failure is in its log. Try again "
            "in a moment, or go back to the fleet.",
            path=request.url.path,
        )

    app.add_exception_handler(LoginRequired, on_login_required)
    app.add_exception_handler(PageError, on_page_error)
    app.add_exception_handler(StarletteHTTPException, on_http_error)
    app.add_exception_handler(RequestValidationError, on_invalid_request)
    app.add_exception_handler(Exception, on_server_error)


# Paths of the API and its machinery: their errors stay JSON ({"detail": ...}).
NOT_PAGES = ("/api/", "/docs", "/redoc", "/openapi", "/metrics", "/healthz", "/readyz", "/static/")
ERROR_PAGES = {
    404: ("Page not found", "There is no page here. The menu above leads to every page."),
    403: ("Not allowed", "Your role does not allow this page."),
    405: ("Not allowed", "This page cannot be used that way."),
}


def _field_of(error: Mapping[str, Any]) -> str:
    """The parameter a validation error is about, as the address or form names it."""
    location = [str(part) for part in error.get("loc", ()) if part not in ("path", "query", "body")]
    return ".".join(location) or "request"


def wants_page(request: Request) -> bool:
    """A browser asking for a dashboard page (HTML), not a client of the API."""
    path = request.url.path
    accepts_html = "text/html" in request.headers.get("accept", "")
    return accepts_html and not path.startswith(NOT_PAGES)


def _quote(path: str) -> str:
    from urllib.parse import quote

    return quote(path, safe="")


def _readable(value: object) -> str:
    """A provenance value for people: nested counts as "name n, ...", lists joined, seconds as
    ages ("inrix age 237 s", not "inrix age s 236.936")."""
    if isinstance(value, dict):
        return ", ".join(_readable_item(name, item) for name, item in value.items())
    if isinstance(value, list):
        return ", ".join(_readable(item) for item in value) or "none"
    if isinstance(value, float):
        return f"{value:.1f}"
    return str(value)


def _readable_pair(name: str, item: object) -> tuple[str, str]:
    """(name, value) for people: a name in seconds loses its unit to the value."""
    if name.endswith("_s") and isinstance(item, int | float) and not isinstance(item, bool):
        return name[:-2], describe_age(float(item))
    return name, _readable(item)


def _readable_item(name: str, item: object) -> str:
    shown_name, shown = _readable_pair(name, item)
    return f"{shown_name.replace('_', ' ')} {shown}"


# --- login --------------------------------------------------------------------------------------


@router.get("/")
async def home() -> RedirectResponse:
    """The fleet page is the dashboard's front page."""
    return RedirectResponse("/fleet", status_code=303)


@router.get("/login")
async def login_form(request: Request, next: str | None = None) -> HTMLResponse:
    """The login form."""
    return _login_page(request, safe_next(next), "", 200)


def _login_page(request: Request, next_path: str, message: str, status_code: int) -> HTMLResponse:
    token = login_csrf_token(request)
    response = _render(
        request,
        "login.html",
        None,
        status_code=status_code,
        next=next_path,
        message=message,
        csrf_token=token,
    )
    remember_login_csrf(request, response, token)
    return response


def _login_limiter(request: Request) -> RateLimiter:
    """Login attempts per client address (the per-account slowdown is in app.users)."""
    state = request.app.state
    limiter: RateLimiter | None = getattr(state, "login_rate_limiter", None)
    if limiter is None:
        per_minute = state.settings.login_attempts_per_minute
        limiter = RateLimiter(per_minute / 60.0, max(1.0, per_minute))
        state.login_rate_limiter = limiter
    return limiter


@router.post("/login")
async def login_submit(
    request: Request,
    session: SessionDep,
    username: Annotated[str, Form()] = "",
    password: Annotated[str, Form()] = "",
    csrf_token: Annotated[str, Form()] = "",
    next: Annotated[str, Form()] = "/fleet",
) -> Response:
    """Check the password; a failure says so, and repeated failures must wait."""
    check_login_csrf(request, csrf_token)
    wait_s = _login_limiter(request).wait_s(request.client.host if request.client else "")
    if wait_s:
        response = _login_page(
            request, safe_next(next), "Too many login attempts from here: wait a minute.", 429
        )
        response.headers.update(retry_after_header(wait_s))
        return response
    result = await log_in(session, username.strip(), password, datetime.now(UTC))
    if result.user is None:
        status_code = 429 if result.retry_after_s else 401
        response = _login_page(request, safe_next(next), result.message, status_code)
        if result.retry_after_s:
            response.headers["Retry-After"] = str(math.ceil(result.retry_after_s))
        return response
    redirect = RedirectResponse(safe_next(next), status_code=303)
    set_session(request, redirect, result.user)
    return redirect


@router.post("/logout")
async def logout(user: UserDep, csrf_token: Annotated[str, Form()] = "") -> RedirectResponse:
    """End the session."""
    check_form(user, csrf_token, needs_operator=False)
    response = RedirectResponse("/login", status_code=303)
    clear_session(response)
    return response


# --- fleet --------------------------------------------------------------------------------------


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
        f"{name}={_quote(value)}"
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
    entries = await fleet(session, now, Thresholds.from_settings(_settings(request)))
    context = _fleet_filters(entries, route, make, problem)
    context["generated_at"] = now
    context["refresh_s"] = _settings(request).dashboard_refresh_s
    context["hold_s"] = _settings(request).readiness_hold_s
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
    return _page(request, user, "fleet", page="fleet", **context)


# --- map --------------------------------------------------------------------------------------


def map_cars(entries: list[FleetEntry], corridor_id: str) -> list[MapCar]:
    """The cars on this corridor with a located last ping, in the map's three states."""
    cars = []
    for entry in entries:
        ping = entry.last_ping
        if entry.vehicle.corridor_id != corridor_id or ping is None or ping.x_m is None:
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
    corridor = next((c for c in corridors if c.corridor_id == corridor_id), None)
    if corridor is None and corridor_id is not None:
        raise PageError(404, "Unknown corridor", f"There is no corridor {corridor_id}.")
    corridor = corridor or (corridors[0] if corridors else None)
    context: dict[str, Any] = {
        "page": "map",
        "corridors": corridors,
        "corridor": corridor,
        "generated_at": now,
        "refresh_s": _settings(request).dashboard_refresh_s,
        "map": None,
        "plan": None,
        "plan_age_s": None,
        "states": {},
    }
    if corridor is None:
        return context
    plan = await data.latest_plan(session, corridor.corridor_id)
    entries = await fleet(session, now, Thresholds.from_settings(_settings(request)))
    cars = map_cars(entries, corridor.corridor_id)
    segments = await data.map_segments(session, corridor.corridor_id, plan)
    if segments:
        upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
        context["map"] = corridor_map("corridor-map", segments, corridor.lanes, cars, upper)
    context["plan"] = plan
    if plan is not None and plan.published_at is not None:
        context["plan_age_s"] = (now - plan.published_at).total_seconds()
    context["states"] = {state: sum(car.state == state for car in cars) for state in CAR_COLOURS}
    return context


@router.get("/map")
@router.get("/map/live")
async def map_page(
    request: Request, user: UserDep, session: SessionDep, corridor: str | None = None
) -> HTMLResponse:
    """The corridor with every car, the plan's targets per lane and the buffers."""
    context = await _map_context(request, session, corridor)
    return _page(request, user, "map", **context)


# --- time-space -------------------------------------------------------------------------------

TIME_SPACE_COLUMNS = 360
TIME_SPACE_ROWS = 200
TIME_SPACE_FIELDS = {"tse": "fused TSE speed", "target": "plan target speed"}


async def _time_space_context(
    request: Request,
    session: AsyncSession,
    corridor_id: str | None,
    lane: int,
    hours: float,
    field_name: str,
) -> dict[str, Any]:
    if field_name not in TIME_SPACE_FIELDS:
        raise PageError(400, "Unknown field", f"Show 'tse' or 'target', not {field_name!r}.")
    settings = _settings(request)
    now = datetime.now(UTC)
    corridors = await data.corridors(session)
    corridor = next((c for c in corridors if c.corridor_id == corridor_id), None)
    if corridor is None and corridor_id is not None:
        raise PageError(404, "Unknown corridor", f"There is no corridor {corridor_id}.")
    corridor = corridor or (corridors[0] if corridors else None)
    context: dict[str, Any] = {
        "page": "timespace",
        "corridors": corridors,
        "corridor": corridor,
        "lane": lane,
        "hours": hours,
        "field": field_name,
        "fields": TIME_SPACE_FIELDS,
        "generated_at": now,
        "refresh_s": _figure_refresh_s(request),
        "figure": None,
        "cars": 0,
        "window_share": None,
        "day_share": None,
        "day_start": None,
    }
    if corridor is None:
        return context
    _check_lane(corridor, lane)
    context["lanes"] = list(range(1, corridor.lanes + 1))
    since = now - timedelta(hours=hours)
    bucket_s = max(1.0, hours * 3600.0 / 720.0)
    trajectories = await data.fleet_trajectories(session, corridor, since, now, bucket_s)
    # The plan in force at `since` was published up to a planner period (and its lag) earlier.
    plans = await data.recent_plans(
        session, corridor.corridor_id, lane, since - timedelta(minutes=15), now
    )
    first = [t.times_s[0] for t in trajectories if len(t.times_s)]
    if plans is not None:
        first.append(float(plans.published_at[0]))
    if not first:
        return context
    start = max(since.timestamp(), min(first))  # the axis begins where the data does
    end = now.timestamp()
    low = corridor.postmile_at_start
    high = low + corridor.length_m / METRES_PER_MILE
    grid = None
    if plans is not None:
        values = plans.tse_mps if field_name == "tse" else plans.target_mps
        times = np.linspace(start, end, TIME_SPACE_COLUMNS, endpoint=False)
        times += (times[1] - times[0]) / 2
        postmiles = np.linspace(low, high, TIME_SPACE_ROWS, endpoint=False)
        postmiles += (postmiles[1] - postmiles[0]) / 2
        grid = data.sample_plans(plans, values, times, postmiles)
        if np.all(np.isnan(grid)):
            grid = None
    upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
    zone = display_zone(settings)
    title = f"{corridor.corridor_id} lane {lane}: {TIME_SPACE_FIELDS[field_name]}, fleet on top"
    context["figure"] = await run_in_threadpool(
        time_space,
        "time-space",
        title,
        grid,
        (datetime.fromtimestamp(start, UTC), now),
        (low, high),
        trajectories,
        zone,
        upper,
        TIME_SPACE_FIELDS[field_name],
        3 * bucket_s,
    )
    context["has_field"] = grid is not None
    context["cars"] = len(trajectories)
    _, context["window_share"] = await data.engagement_share(
        session, corridor.corridor_id, since, now
    )
    day_start = datetime.combine(now.astimezone(zone).date(), datetime.min.time(), zone)
    context["day_start"] = day_start
    _, context["day_share"] = await data.engagement_share(
        session, corridor.corridor_id, day_start, now
    )
    return context


@router.get("/timespace")
@router.get("/timespace/live")
async def time_space_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    corridor: str | None = None,
    lane: Annotated[int, Query(ge=1, le=12)] = 1,
    hours: Annotated[float, Query(gt=0, le=24)] = 2.0,
    field: str = "tse",
) -> HTMLResponse:
    """The paper's time-space view: the speed field with every fleet car's trajectory on top."""
    context = await _time_space_context(request, session, corridor, lane, hours, field)
    return _page(request, user, "timespace", **context)


# --- vehicle ------------------------------------------------------------------------------------


async def _entry_or_404(request: Request, session: SessionDep, vehicle_id: str) -> FleetEntry:
    try:
        return await vehicle_entry(
            session,
            vehicle_id,
            datetime.now(UTC),
            Thresholds.from_settings(_settings(request)),
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


def _over_time(
    chart_id: str,
    title: str,
    series: Series,
    x_axis: Axis,
    y_axis: Axis,
    zone: ZoneInfo,
    *,
    height: int = 240,
) -> Any:
    """One quantity over time, drawn as points while there are fewer than three of them (a
    line through one or two values hides them)."""
    style: Literal["points", "line"] = "points" if len(series.x) < 3 else "line"
    return chart(
        chart_id,
        line_figure(
            title, [replace(series, style=style)], x_axis, y_axis, height=height, zone=zone
        ),
    )


def _engagement_chart(chart_id: str, title: str, rows: Any, zone: ZoneInfo) -> Any:
    """Engagement share per local day, as bars (vehicle and analytics pages)."""
    return chart(
        chart_id,
        bar_figure(
            title,
            [row["day"].strftime("%m-%d") for row in rows],
            [100.0 * row["engagement_share"] for row in rows],
            f"day ({zone.key})",
            Axis("time with controller engaged (%)", lower=0.0, upper=100.0),
            value_format="{:.0f} %",
        ),
    )


def local_days_ago(now: datetime, zone: ZoneInfo, days: int) -> datetime:
    """The start of the local day `days` days before `now`'s (charts per day begin there)."""
    day = now.astimezone(zone).date() - timedelta(days=days)
    return datetime.combine(day, datetime.min.time(), zone)


async def _vehicle_history(
    request: Request, session: AsyncSession, entry: FleetEntry
) -> dict[str, Any]:
    """The car's recent past: speed against its plan, engagement per local day, its reports."""
    vehicle_id = entry.vehicle.vehicle_id
    now = datetime.now(UTC)
    zone = display_zone(_settings(request))
    context: dict[str, Any] = {
        "entry": entry,
        "history_generated_at": now,
        "history_refresh_s": _figure_refresh_s(request),
        "zone_name": zone.key,
        "speed_chart": None,
        "engagement_chart": None,
    }
    if entry.last_ping is not None:
        trace = await data.vehicle_trace(session, vehicle_id, entry.last_ping.ts, TRACE_WINDOW)
        if trace.ts:
            context["speed_chart"] = _speed_chart(entry, trace, zone)
    context["statuses"] = await data.status_history(session, vehicle_id)
    engagement = await data.engagement_per_day(
        session, local_days_ago(now, zone, ANALYTICS_DAYS), zone, vehicle_id=vehicle_id
    )
    context["engagement"] = engagement
    if engagement:
        context["engagement_chart"] = _engagement_chart(
            "vehicle-engagement", f"Engagement of {vehicle_id} per day", engagement, zone
        )
    return context


async def _vehicle_context(
    request: Request, session: SessionDep, vehicle_id: str
) -> dict[str, Any]:
    entry = await _entry_or_404(request, session, vehicle_id)
    return {
        "entry": entry,
        "generated_at": datetime.now(UTC),
        "refresh_s": _settings(request).dashboard_refresh_s,
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
    return _render(
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
    """The vehicle's verdict and checks, for the page's periodic refresh."""
    entry = await _entry_or_404(request, session, vehicle_id)
    return _render(request, "_vehicle_live.html", user, entry=entry, generated_at=datetime.now(UTC))


@router.get("/vehicles/{vehicle_id}/history/live")
async def vehicle_history_live(
    request: Request, user: UserDep, session: SessionDep, vehicle_id: VehicleId
) -> HTMLResponse:
    """The vehicle's speed chart, engagement and status reports, for their periodic refresh."""
    entry = await _entry_or_404(request, session, vehicle_id)
    context = await _vehicle_history(request, session, entry)
    return _render(request, "_vehicle_history_live.html", user, **context)


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
    return _render(
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


def _config_version_read(config_version: str) -> int | None:
    """The config version the form was filled in against (its hidden field); none from a
    client that sends none, which saves without the check, as the API does."""
    if not config_version:
        return None
    if not (config_version.isascii() and config_version.isdigit()):
        raise AssignmentError("config_version", f"{config_version!r} is not a config version")
    return int(config_version)


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
            raise AssignmentError("lane", f"{lane!r} is not a lane number") from None
        try:
            controller_params = json.loads(params or "{}")
        except json.JSONDecodeError as error:
            raise AssignmentError("controller.params", f"not valid JSON ({error.msg})") from None
        if not isinstance(controller_params, dict):
            raise AssignmentError("controller.params", "must be a JSON object")
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
    try:
        await set_maintenance(
            session,
            vehicle_id,
            in_maintenance=in_maintenance in ("on", "true", "1"),
            note=note,
            changed_by=f"dashboard user {user.username}",
            expected_config_version=_config_version_read(config_version),
        )
    except AssignmentError as error:
        return await _not_saved(request, session, user, vehicle_id, error)
    return RedirectResponse(f"/vehicles/{vehicle_id}?saved=maintenance", status_code=303)


# --- plans --------------------------------------------------------------------------------------


def _plan_charts(profiles: list[data.LaneProfile]) -> list[tuple[int, Any]]:
    charts = []
    for profile in profiles:
        x = [
            value
            for pair in zip(profile.start_postmile, profile.end_postmile, strict=True)
            for value in pair
        ]
        target = [v * MPH_PER_MPS for v in profile.target_mps for _ in range(2)]
        tse = [None if v is None else v * MPH_PER_MPS for v in profile.tse_mps for _ in range(2)]
        charts.append(
            (
                profile.lane,
                chart(
                    f"plan-lane-{profile.lane}",
                    line_figure(
                        f"Target speed of lane {profile.lane} along the corridor",
                        [
                            Series("fused TSE", x, tse, "#9ca3af"),
                            Series("target speed", x, target, "#2563eb"),
                        ],
                        Axis("postmile (direction of travel →)"),
                        Axis("speed (mph)", lower=0.0),
                        bands=[Band(start, end) for start, end in profile.buffers()],
                        band_label="buffer region",
                        height=240,
                    ),
                ),
            )
        )
    return charts


def _time_space_chart(
    chart_id: str,
    title: str,
    field: data.TimeSpace,
    values: np.ndarray[Any, np.dtype[np.float64]],
    since: datetime,
    until: datetime,
    speed_upper_mph: float,
    zone: ZoneInfo,
) -> Any:
    times = np.linspace(since.timestamp(), until.timestamp(), HEATMAP_COLUMNS, endpoint=False)
    times += (times[1] - times[0]) / 2
    low, high = field.segment_edges_postmile[0], field.segment_edges_postmile[-1]
    postmiles = np.linspace(low, high, HEATMAP_ROWS, endpoint=False)
    postmiles += (postmiles[1] - postmiles[0]) / 2
    grid = data.sample_plans(field, values, times, postmiles) * MPH_PER_MPS
    return chart(
        chart_id,
        heatmap_figure(
            title,
            grid,
            (since.timestamp(), until.timestamp()),
            (float(low), float(high)),
            Axis("time", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, speed_upper_mph, "speed (mph)"),
            zone=zone,
        ),
    )


def _check_lane(corridor: Corridor, lane: int) -> None:
    """A lane the corridor does not have is refused by name: the lane menu would show its first
    lane while the page drew the asked one, and its next refresh would switch lanes unasked."""
    if lane > corridor.lanes:
        raise PageError(
            422,
            "Unknown lane",
            f"{corridor.corridor_id} has lanes 1 to {corridor.lanes}, not {lane}.",
        )


async def _plans_context(
    request: Request,
    session: AsyncSession,
    plan: PlanRun | None,
    corridor_id: str | None,
    lane: int,
) -> dict[str, Any]:
    """A plan run (None: the corridor's latest) with its charts, and the recent runs."""
    corridors = await data.corridors(session)
    wanted = plan.corridor_id if plan else corridor_id
    corridor = next((c for c in corridors if c.corridor_id == wanted), None)
    if corridor is None and wanted is not None:
        # another corridor's plans under a mistyped or old link would read as this one's
        raise PageError(404, "Unknown corridor", f"There is no corridor {wanted}.")
    corridor = corridor or (corridors[0] if corridors else None)
    context: dict[str, Any] = {
        "page": "plans",
        "corridors": corridors,
        "corridor": corridor,
        "plan": plan,
        "lane": lane,
        "lane_charts": [],
        "runs": [],
        "target_map": None,
        "tse_map": None,
        "inputs": {},
        "params": "",
        "fixed_plan": plan is not None,
        "generated_at": datetime.now(UTC),
        "refresh_s": _figure_refresh_s(request),
    }
    if corridor is None:
        return context
    _check_lane(corridor, lane)
    if plan is None:
        plan = await data.latest_plan(session, corridor.corridor_id)
        context["plan"] = plan
    context["runs"] = await data.plan_runs(session, corridor.corridor_id)
    context["lanes"] = list(range(1, corridor.lanes + 1))
    if plan is None:
        return context
    context["inputs"] = dict(_readable_pair(name, value) for name, value in plan.inputs.items())
    context["params"] = json.dumps(plan.params, indent=1, sort_keys=True)
    context["lane_charts"] = _plan_charts(await data.plan_profiles(session, plan))
    # The hour of plans up to this one, drawn until this plan stops being in force (or now).
    published = plan.published_at or plan.started_at
    until = max(
        published + timedelta(seconds=_settings(request).planner_period_s),
        min(datetime.now(UTC), plan.valid_until or published),
    )
    since = published - PLAN_HISTORY
    field = await data.recent_plans(session, corridor.corridor_id, lane, since, published)
    if field is not None:
        # The time axis begins with the first plan drawn, not an hour before it.
        since = max(since, datetime.fromtimestamp(float(field.published_at[0]), UTC))
        upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
        zone = display_zone(_settings(request))
        context["target_map"] = _time_space_chart(
            "plan-heatmap",
            f"Target speed of lane {lane}, recent plans",
            field,
            field.target_mps,
            since,
            until,
            upper,
            zone,
        )
        if not np.all(np.isnan(field.tse_mps)):
            context["tse_map"] = _time_space_chart(
                "tse-heatmap",
                f"Fused traffic state (TSE) of lane {lane}",
                field,
                field.tse_mps,
                since,
                until,
                upper,
                zone,
            )
    return context


@router.get("/plans")
@router.get("/plans/live")
async def plans_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    corridor: str | None = None,
    lane: Annotated[int, Query(ge=1, le=12)] = 1,
) -> HTMLResponse:
    """The latest plan of a corridor: targets per lane, buffers, time-space maps, provenance."""
    context = await _plans_context(request, session, None, corridor, lane)
    return _page(request, user, "plans", **context)


@router.get("/plans/{plan_id}")
async def plan_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    plan_id: PlanId,
    lane: Annotated[int, Query(ge=1, le=12)] = 1,
) -> HTMLResponse:
    """One plan run by id."""
    plan = await data.plan_by_id(session, plan_id)
    if plan is None:
        raise PageError(
            404,
            "Unknown plan",
            f"There is no plan {plan_id}. The plans page lists the recent runs.",
        )
    context = await _plans_context(request, session, plan, plan.corridor_id, lane)
    return _render(request, "plans.html", user, **context)


# --- feeds --------------------------------------------------------------------------------------


@router.get("/feeds")
@router.get("/feeds/live")
async def feeds_page(request: Request, user: UserDep, session: SessionDep) -> HTMLResponse:
    """INRIX freshness and latency, pings per second, rejected inputs."""
    context = await _feeds_context(request, session)
    return _page(request, user, "feeds", **context)


async def _feeds_context(request: Request, session: AsyncSession) -> dict[str, Any]:
    now = datetime.now(UTC)
    latest = await data.latest_inrix(session)
    inrix_since = now - timedelta(hours=6)
    ping_since = now - timedelta(hours=1)
    snapshots = await data.inrix_snapshots(session, inrix_since)
    # Only whole minutes of GPS time: the minute still running has a fraction of its pings.
    minutes = [
        row
        for row in await data.pings_per_minute(session, ping_since)
        if row["minute"] + timedelta(minutes=1) <= now
    ]
    context: dict[str, Any] = {
        "page": "feeds",
        "latest": latest,
        "latest_age_s": None if latest is None else (now - latest["measured_at"]).total_seconds(),
        "minutes": minutes,
        "rejected": data.rejected_inputs(),
        "inrix_chart": None,
        "ping_chart": None,
        "last_minute": minutes[-1] if minutes else None,
        # how long ago the newest whole minute with pings ended: a fleet silent for 50 minutes
        # must not read as a live feed
        "last_minute_age_s": (
            (now - minutes[-1]["minute"] - timedelta(minutes=1)).total_seconds()
            if minutes
            else None
        ),
        "generated_at": now,
        "refresh_s": _figure_refresh_s(request),
    }
    zone = display_zone(_settings(request))
    if snapshots:
        context["inrix_chart"] = _over_time(
            "inrix-latency",
            "INRIX latency per snapshot",
            Series(
                "latency",
                [row["measured_at"].timestamp() for row in snapshots],
                [row["latency_s"] for row in snapshots],
                "#9333ea",
            ),
            Axis("INRIX measurement time", "time"),
            Axis("latency: received − measured (s)", lower=0.0),
            zone,
        )
    if minutes:
        context["ping_chart"] = _over_time(
            "ping-rate",
            "Pings per second, per minute of GPS time",
            Series(
                "pings per second",
                [row["minute"].timestamp() for row in minutes],
                [row["pings"] / 60.0 for row in minutes],
                "#2563eb",
            ),
            Axis("time", "time"),
            Axis("pings per second", lower=0.0),
            zone,
        )
    return context


# --- analytics ----------------------------------------------------------------------------------


@router.get("/analytics")
@router.get("/analytics/live")
async def analytics_page(request: Request, user: UserDep, session: SessionDep) -> HTMLResponse:
    """Engagement per day, pings and vehicles per hour, plan adherence, Edie fields.

    The figures cover days and hours (and a week of plan adherence, the costly part), so each
    server process computes them at most once every ANALYTICS_REFRESH_S and serves that copy,
    which the page polls for as often; it says when the copy was computed.
    """
    cached: tuple[datetime, dict[str, Any]] | None = getattr(
        request.app.state, "analytics_page", None
    )
    now = datetime.now(UTC)
    if cached is None or (now - cached[0]).total_seconds() >= ANALYTICS_REFRESH_S:
        cached = (now, await _analytics_context(session, now, display_zone(_settings(request))))
        request.app.state.analytics_page = cached
    computed_at, context = cached
    return _page(
        request,
        user,
        "analytics",
        generated_at=computed_at,
        refresh_s=ANALYTICS_REFRESH_S,
        **context,
    )


async def _analytics_context(
    session: AsyncSession, now: datetime, zone: ZoneInfo
) -> dict[str, Any]:
    """What the analytics page shows, as of `now`."""
    engagement = await data.engagement_per_day(
        session, local_days_ago(now, zone, ANALYTICS_DAYS), zone
    )
    hourly_since = (now - timedelta(hours=48)).replace(minute=0, second=0, microsecond=0)
    hourly = await data.fleet_pings_hourly(session, hourly_since)
    adherence = await data.adherence_per_day(
        session, local_days_ago(now, zone, ADHERENCE_DAYS), zone
    )
    context: dict[str, Any] = {
        "page": "analytics",
        "zone_name": zone.key,
        "engagement": engagement,
        "hourly": hourly,
        "adherence": adherence,
        "charts": {},
        "edie_window": None,
    }
    charts = context["charts"]
    if engagement:
        charts["engagement"] = _engagement_chart(
            "engagement-share",
            "Share of fleet time with the controller engaged, per day",
            engagement,
            zone,
        )
    if hourly:
        hours = [row["hour"].timestamp() + 1800.0 for row in hourly]  # middle of the hour
        charts["pings"] = _over_time(
            "pings-hourly",
            "Pings per hour (the hour in progress at its rate so far)",
            Series("pings", hours, pings_per_hour(hourly), "#2563eb"),
            Axis("hour", "time"),
            Axis("pings per hour", lower=0.0),
            zone,
            height=220,
        )
        charts["vehicles"] = _over_time(
            "vehicles-hourly",
            "Vehicles heard per hour",
            Series("vehicles", hours, [float(r["vehicles"]) for r in hourly], "#16a34a"),
            Axis("hour", "time"),
            Axis("vehicles", lower=0.0),
            zone,
            height=220,
        )
    if adherence:
        charts["adherence"] = chart(
            "plan-adherence",
            bar_figure(
                "Mean |speed − plan target| per day",
                [row["day"].strftime("%m-%d") for row in adherence],
                [row["mean_abs_speed_error_mps"] * MPH_PER_MPS for row in adherence],
                f"day ({zone.key})",
                Axis("mean |speed − target| (mph)", lower=0.0),
                value_format="{:.1f}",
                colour="#dc2626",
            ),
        )
    await _edie_charts(session, context, zone)
    return context


def pings_per_hour(hourly: Sequence[RowMapping]) -> list[float]:
    """Each hour's pings per hour: its mean rate (`analytics.fleet_ping_hourly.pings_per_s`)
    times 3,600 s.

    For an hour that is over this is its count of pings. The hour in progress is at its rate so
    far, as the view divides it by the seconds it has run (migration 0011): its count, plotted
    before, always ended the chart in a dip (half the fleet's pings at half past) that read as
    the fleet going quiet."""
    return [float(row["pings_per_s"]) * 3600.0 for row in hourly]


async def _edie_charts(session: SessionDep, context: dict[str, Any], zone: ZoneInfo) -> None:
    """Bulk speed and fuel per distance of the last hour with pings (paper, Results)."""
    newest = await data.newest_ping_ts(session)
    corridors = await data.corridors(session)
    if newest is None or not corridors:
        return
    corridor = corridors[0]
    until = newest + timedelta(seconds=1)
    since = until - timedelta(hours=1)
    boxes = await data.edie_field(session, since, until, corridor.corridor_id)
    if not boxes:
        return
    h_t, h_x = 10.0, 200.0
    t0 = math.floor(since.timestamp() / h_t) * h_t
    columns = math.ceil((until.timestamp() - t0) / h_t)
    rows = math.ceil(corridor.length_m / h_x)
    speed = np.full((rows, columns), np.nan)
    fuel = np.full((rows, columns), np.nan)
    for box in boxes:
        column = int(round((box["t_start"].timestamp() - t0) / h_t))
        row = int(round(box["x_start_m"] / h_x))
        if 0 <= row < rows and 0 <= column < columns:
            speed[row, column] = box["speed_mps"] * MPH_PER_MPS
            if box["fuel_per_distance_g_per_m"] is not None:
                fuel[row, column] = box["fuel_per_distance_g_per_m"] * 1000.0
    postmiles = (
        corridor.postmile_at_start,
        corridor.postmile_at_start + rows * h_x / METRES_PER_MILE,
    )
    x_range = (t0, t0 + columns * h_t)
    context["edie_window"] = (since, until, corridor.corridor_id)
    upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
    context["charts"]["edie_speed"] = chart(
        "edie-speed",
        heatmap_figure(
            "Bulk speed u = q / ρ of the fleet's pings",
            speed,
            x_range,
            postmiles,
            Axis("time", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, upper, "bulk speed (mph)"),
            zone=zone,
        ),
    )
    finite = fuel[np.isfinite(fuel)]
    fuel_upper = float(np.percentile(finite, 95)) if finite.size else 1.0
    context["charts"]["edie_fuel"] = chart(
        "edie-fuel",
        heatmap_figure(
            "Bulk fuel consumption ψ = f / q",
            fuel,
            x_range,
            postmiles,
            Axis("time", "time"),
            Axis("postmile (direction of travel ↑)"),
            ColourScale(0.0, max(fuel_upper, 1e-3), "fuel per distance (g/km)", AMOUNT_STOPS),
            zone=zone,
        ),
    )
