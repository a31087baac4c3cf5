"""The dashboard as one site on the app: its pages (one module each under
`dashboards.pages`), their static files, and error pages for browsers.

A browser asking for a page gets an error as a page (404, 403, a parameter the page refuses, a
server failure); a client of the API gets the API's JSON errors.
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Mapping
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, PlainTextResponse, RedirectResponse, Response
from fastapi.staticfiles import StaticFiles
from starlette.exceptions import HTTPException as StarletteHTTPException

from dashboards.auth import (
    LoginRequired,
    PageError,
    SessionRenewal,
    is_live_refresh,
    navigating_user,
)
from dashboards.pages import (
    analytics,
    feeds,
    fleet,
    fleet_map,
    login,
    motion,
    plans,
    timespace,
    vehicle,
)
from dashboards.rendering import DASHBOARD_DIR, quote_path, render

log = logging.getLogger(__name__)

# Every page module, in the order their routes are matched.
PAGES = (login, fleet, fleet_map, timespace, vehicle, plans, feeds, analytics, motion)


def install(app: FastAPI) -> None:
    """Mount the pages, their static files and their error pages on the app."""
    for pages in PAGES:
        app.include_router(pages.router)
    app.add_middleware(SessionRenewal)
    app.mount("/static", StaticFiles(directory=DASHBOARD_DIR / "static"), name="static")

    async def on_login_required(request: Request, error: Exception) -> Response:
        assert isinstance(error, LoginRequired)
        if is_live_refresh(request):
            return JSONResponse({"detail": "log in again"}, status_code=401)
        return RedirectResponse(f"/login?next={quote_path(error.next_path)}", status_code=303)

    async def on_page_error(request: Request, error: Exception) -> Response:
        assert isinstance(error, PageError)
        return render(
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
        return render(
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
        return render(
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
        return render(
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
