"""The plans pages: a corridor's latest plan (or one by id) with its target speed per lane, its
buffers, the time-space maps of the recent plans and what the plan was made from.
"""

from __future__ import annotations

import json
import math
from collections import OrderedDict
from datetime import UTC, datetime, timedelta
from typing import Annotated, Any
from zoneinfo import ZoneInfo

import numpy as np
from fastapi import APIRouter, Request
from fastapi import Path as PathParameter
from fastapi.responses import HTMLResponse
from markupsafe import Markup
from sqlalchemy.ext.asyncio import AsyncSession
from starlette.concurrency import run_in_threadpool

from app.core.sessions import SessionDep
from app.fleet.readiness import describe_age
from app.models import PlanRun
from contract.units import MPH_PER_MPS
from dashboards import data
from dashboards.auth import PageError, UserDep
from dashboards.charts import Axis, Band, ColourScale, Series, chart, heatmap_figure, line_figure
from dashboards.pages.corridor_choice import LaneNumber, check_lane, chosen_corridor
from dashboards.rendering import (
    display_zone,
    figure_refresh_s,
    local_time,
    page,
    render,
    settings_of,
)

router = APIRouter(include_in_schema=False)

# The plan id is checked as the API checks it, before any query: one beyond plan_run.plan_id's
# bigint was refused by the database instead, and its refusal reached a browser as the API's
# JSON 422, not a page.
PlanId = Annotated[int, PathParameter(ge=1, le=2**63 - 1)]
PLAN_HISTORY = timedelta(minutes=60)
HEATMAP_COLUMNS = 240
HEATMAP_ROWS = 180
# Lane charts kept per server process: those of the plans people look at (the latest of each
# corridor, and the few before it they open by id).
LANE_CHARTS_KEPT = 8


class LaneChartCache:
    """The lane charts of the plans drawn last, by plan id, the most recently used kept.

    A plan run is written once and never changes, so its lane charts need drawing once: at
    about 0.1 s a chart (`python -m bench.charts`), a plans page refreshing every 15 s drew its
    four lane charts again three times in each minute of a plan.
    """

    def __init__(self, kept: int = LANE_CHARTS_KEPT) -> None:
        if kept < 1:
            raise ValueError(f"a lane chart cache keeps at least one plan, got {kept}")
        self.kept = kept
        self._charts: OrderedDict[int, list[tuple[int, Markup]]] = OrderedDict()

    def get(self, plan_id: int) -> list[tuple[int, Markup]] | None:
        """The plan's lane charts if kept (and now the most recently used)."""
        charts = self._charts.get(plan_id)
        if charts is not None:
            self._charts.move_to_end(plan_id)
        return charts

    def put(self, plan_id: int, charts: list[tuple[int, Markup]]) -> None:
        """Keep the plan's lane charts, forgetting the least recently used beyond `kept`."""
        self._charts[plan_id] = charts
        self._charts.move_to_end(plan_id)
        while len(self._charts) > self.kept:
            self._charts.popitem(last=False)


def _lane_chart_cache(request: Request) -> LaneChartCache:
    cache: LaneChartCache | None = getattr(request.app.state, "plan_lane_charts", None)
    if cache is None:
        cache = request.app.state.plan_lane_charts = LaneChartCache()
    return cache


def _readable(value: object, zone: ZoneInfo) -> str:
    """A provenance value for people: nested counts as "name n, ...", lists joined, seconds as
    ages ("inrix age 237 s", not "inrix age s 236.936"), times in the page's zone as the rows
    beside them are (not raw UTC ISO text), and nothing as a dash (not "None")."""
    if value is None:
        return "—"
    if isinstance(value, dict):
        return ", ".join(_readable_item(name, item, zone) for name, item in value.items())
    if isinstance(value, list):
        return ", ".join(_readable(item, zone) for item in value) or "none"
    if isinstance(value, float):
        return f"{value:.1f}"
    if isinstance(value, str):
        return _local_time_text(value, zone) or value
    return str(value)


def _local_time_text(text: str, zone: ZoneInfo) -> str | None:
    """An ISO 8601 time with a zone, as the page's other times are written; None if `text` is
    not one."""
    if "T" not in text:
        return None
    try:
        moment = datetime.fromisoformat(text)
    except ValueError:
        return None
    if moment.tzinfo is None:
        return None
    return local_time(moment, zone)


def readable_input(name: str, item: object, zone: ZoneInfo) -> tuple[str, str]:
    """(name, value) for people: a name in seconds loses its unit to the value."""
    if name.endswith("_s") and isinstance(item, int | float) and not isinstance(item, bool):
        return name[:-2], describe_age(float(item))
    if name.endswith("_s") and item is None:
        return name[:-2], "—"
    return name, _readable(item, zone)


def _readable_item(name: str, item: object, zone: ZoneInfo) -> str:
    shown_name, shown = readable_input(name, item, zone)
    return f"{shown_name.replace('_', ' ')} {shown}"


def _plan_charts(profiles: list[data.LaneProfile]) -> list[tuple[int, Markup]]:
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


async def _plans_context(
    request: Request,
    session: AsyncSession,
    plan: PlanRun | None,
    corridor_id: str | None,
    lane: int,
) -> dict[str, Any]:
    """A plan run (None: the corridor's latest) with its charts, and the recent runs."""
    corridors = await data.corridors(session)
    corridor = chosen_corridor(corridors, plan.corridor_id if plan else corridor_id)
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
        "refresh_s": figure_refresh_s(request),
    }
    if corridor is None:
        return context
    check_lane(corridor, lane)
    if plan is None:
        plan = await data.latest_plan(session, corridor.corridor_id)
        context["plan"] = plan
    context["runs"] = await data.plan_runs(session, corridor.corridor_id)
    context["lanes"] = list(range(1, corridor.lanes + 1))
    if plan is None:
        return context
    shown_in = display_zone(settings_of(request))
    context["inputs"] = dict(
        readable_input(name, value, shown_in) for name, value in plan.inputs.items()
    )
    context["params"] = json.dumps(plan.params, indent=1, sort_keys=True)
    cache = _lane_chart_cache(request)
    lane_charts = cache.get(plan.plan_id)
    if lane_charts is None:
        profiles = await data.plan_profiles(session, plan)
        lane_charts = await run_in_threadpool(_plan_charts, profiles)
        cache.put(plan.plan_id, lane_charts)
    context["lane_charts"] = lane_charts
    # The hour of plans up to this one, drawn until this plan stops being in force (or now).
    published = plan.published_at or plan.started_at
    until = max(
        published + timedelta(seconds=settings_of(request).planner_period_s),
        min(datetime.now(UTC), plan.valid_until or published),
    )
    since = published - PLAN_HISTORY
    field = await data.recent_plans(session, corridor.corridor_id, lane, since, published)
    if field is not None:
        # The time axis begins with the first plan drawn, not an hour before it.
        since = max(since, datetime.fromtimestamp(float(field.published_at[0]), UTC))
        upper = math.ceil(corridor.speed_limit_mps * MPH_PER_MPS / 5) * 5
        zone = display_zone(settings_of(request))
        context["target_map"] = await run_in_threadpool(
            _time_space_chart,
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
            context["tse_map"] = await run_in_threadpool(
                _time_space_chart,
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
    lane: LaneNumber = 1,
) -> HTMLResponse:
    """The latest plan of a corridor: targets per lane, buffers, time-space maps, provenance."""
    context = await _plans_context(request, session, None, corridor, lane)
    return page(request, user, "plans", **context)


@router.get("/plans/{plan_id}")
async def plan_page(
    request: Request,
    user: UserDep,
    session: SessionDep,
    plan_id: PlanId,
    lane: LaneNumber = 1,
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
    return render(request, "plans.html", user, **context)
