"""The login form and logout. Login attempts are limited per client here and per (account,
client) in `app.users`, a client being its `login_client_key` (an IPv4 address or an IPv6 /64)
in both; a failure says so, and repeated failures must wait.
"""

from __future__ import annotations

import math
from datetime import UTC, datetime
from typing import Annotated

from fastapi import APIRouter, Form, Request
from fastapi.responses import HTMLResponse, RedirectResponse, Response

from app.core.ratelimit import RateLimiter, retry_after_header
from app.core.sessions import SessionDep
from app.users.client_key import login_client_key
from app.users.service import end_sessions, log_in
from dashboards.auth import (
    UserDep,
    check_form,
    check_login_csrf,
    clear_session,
    login_csrf_token,
    remember_login_csrf,
    safe_next,
    set_session,
)
from dashboards.rendering import render

router = APIRouter(include_in_schema=False)


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
    response = render(
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
    """Login attempts per client (the per-account slowdown is in app.users)."""
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
    # one key for both limits: an IPv6 client counted by its full address took a fresh
    # allowance with every address of its /64
    client_key = login_client_key(request.client.host if request.client else None)
    wait_s = _login_limiter(request).wait_s(client_key)
    if wait_s:
        response = _login_page(
            request, safe_next(next), "Too many login attempts from here: wait a minute.", 429
        )
        response.headers.update(retry_after_header(wait_s))
        return response
    result = await log_in(session, username.strip(), password, client_key, datetime.now(UTC))
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
async def logout(
    user: UserDep, session: SessionDep, csrf_token: Annotated[str, Form()] = ""
) -> RedirectResponse:
    """End the user's sessions: this browser's cookie, and every cookie issued to the user
    before now (`ops_user.sessions_valid_from`). Deleting the cookie alone left a copy of it
    valid for the rest of its 12 h."""
    check_form(user, csrf_token, needs_operator=False)
    await end_sessions(session, user.username, datetime.now(UTC))
    response = RedirectResponse("/login", status_code=303)
    clear_session(response)
    return response
