"""How every dashboard page is rendered: one Jinja2 environment with the filters people read,
and a page or only its live part.

Speeds are shown in mph and places in postmiles (people's units on US roads); times in the
corridor's local time (`dashboard_timezone`).

Pages are rendered on the server with their charts drawn by matplotlib (PNG inside the page),
on a worker thread (`charts.drawn`), never on the event loop the ingest API shares; a page that
refreshes itself fetches its `.../live` path, which renders the same context into the page's
live part (static/dashboard.js).
"""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from urllib.parse import quote
from zoneinfo import ZoneInfo

from fastapi import Request
from fastapi.responses import HTMLResponse
from fastapi.templating import Jinja2Templates
from jinja2 import pass_context
from jinja2.runtime import Context

from app.core.config import Settings
from app.fleet.readiness import describe_age
from app.policies.service import bundled_policy_sha256
from contract.units import MPH_PER_MPS
from dashboards.auth import PageUser

DASHBOARD_DIR = Path(__file__).parent
templates = Jinja2Templates(directory=DASHBOARD_DIR / "templates")

# Parts of pages drawn with matplotlib refresh at most this often (s): a figure costs about
# 0.1 s of the server's CPU (the vehicle page's speed chart 87-100 ms, `python -m bench.charts`),
# and what they show changes by the minute (plans, INRIX) or slowly.
FIGURE_MIN_REFRESH_S = 15.0


def _mph(value: float | None) -> str:
    return "—" if value is None else f"{value * MPH_PER_MPS:.1f}"


def display_zone(settings: Settings) -> ZoneInfo:
    """The time zone people read times in (the corridor's)."""
    return ZoneInfo(settings.dashboard_timezone)


def local_time(moment: datetime, zone: ZoneInfo) -> str:
    """A moment as every page writes times: in the corridor's zone, to the second, zone named."""
    return moment.astimezone(zone).strftime("%Y-%m-%d %H:%M:%S %Z")


@pass_context
def _localtime(context: Context, value: datetime | None) -> str:
    if value is None:
        return "—"
    return local_time(value, display_zone(context["request"].app.state.settings))


# The roster's fields in the words the vehicle page uses for them, in the roster's column order.
ROSTER_FIELD_WORDS = {
    "vin": "VIN",
    "make": "make",
    "model": "model",
    "year": "year",
    "actuation": "actuation",
    "corridor_id": "corridor",
    "route": "route",
    "assigned_lane": "lane",
    "controller_name": "controller",
    "controller_params": "controller parameters",
}


def _roster_value(value: Any) -> str:
    return json.dumps(value, sort_keys=True) if isinstance(value, dict) else str(value)


def roster_changes(changed: dict[str, list[Any]]) -> str:
    """What a roster import changed, `lane 1 → 3; controller parameters {} → {...}`: the values
    the row set alone read a change of the parameters, corridor or actuation as none, and a
    moved lane as the lane it had always had."""
    return "; ".join(
        f"{words} {_roster_value(changed[name][0])} → {_roster_value(changed[name][1])}"
        for name, words in ROSTER_FIELD_WORDS.items()
        if name in changed
    )


templates.env.filters["mph"] = _mph
templates.env.filters["roster_changes"] = roster_changes
templates.env.filters["localtime"] = _localtime
templates.env.filters["age"] = describe_age
templates.env.globals["bundled_policy"] = bundled_policy_sha256


def settings_of(request: Request) -> Settings:
    """The settings of the app serving this request."""
    settings: Settings = request.app.state.settings
    return settings


def render(
    request: Request,
    name: str,
    user: PageUser | None,
    status_code: int = 200,
    **context: Any,
) -> HTMLResponse:
    """Template `name` with the logged-in user (None on the login page) and the time now."""
    return templates.TemplateResponse(
        request,
        name,
        {"user": user, "now": datetime.now(UTC), **context},
        status_code=status_code,
    )


def figure_refresh_s(request: Request) -> float:
    """How often a part of a page drawn with matplotlib refreshes itself."""
    return max(settings_of(request).dashboard_refresh_s, FIGURE_MIN_REFRESH_S)


def page(request: Request, user: PageUser, name: str, **context: Any) -> HTMLResponse:
    """Page `name`, or at its `/live` path only the part that refreshes itself (the page polls
    it; static/dashboard.js): one handler and one context serve both."""
    if request.url.path.endswith("/live"):
        return render(request, f"_{name}_live.html", user, **context)
    return render(request, f"{name}.html", user, **context)


def quote_path(path: str) -> str:
    """A path or value quoted whole for a query string (`/login?next=...`, filter links)."""
    return quote(path, safe="")
