"""Dashboard sessions: a signed cookie after login, CSRF tokens for every form, role checks.

The cookie holds the username, when it was issued, when its user last did something, a random
session nonce and a fingerprint of the user's password hash, signed with HMAC-SHA256 under a
key derived from SMOOTHFLEET_SECRET_KEY. Every request reloads the user, so a changed role
applies at once and a changed password (new fingerprint) ends every old session. Forms carry a
CSRF token derived from the session nonce; the login form, which has no session yet, uses a
double-submit cookie.

A session ends `dashboard_session_max_age_s` after its login (12 h) and, since 2026-12-05,
after `dashboard_session_idle_s` without activity (60 min): a dashboard left open on an
unattended desk no longer stays an operator's for the rest of the 12 h. Each page the user
asks for, and each form sent, renews the cookie's time of activity; the refreshes a page's
script makes on its own (`X-Requested-With: fetch`, the `.../live` parts) do not, or a fleet
page left open would never be idle. Such a page sends its user to the login form at its first
refresh after the idle limit. The renewed cookie is added to the response by `SessionRenewal`:
FastAPI drops the headers a dependency sets when the page returns a response of its own.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import math
import secrets
import time
from dataclasses import dataclass, replace
from typing import Annotated

from fastapi import Depends, Request, Response
from sqlalchemy import select
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from app.core.config import Settings
from app.core.sessions import SessionDep
from app.models import OpsUser

SESSION_COOKIE = "sf_session"
# What the dashboard's script sends with the refreshes it makes on its own (static/dashboard.js).
LIVE_REFRESH_HEADER = ("x-requested-with", "fetch")
# Where `current_user` leaves the renewed session's Set-Cookie value for `SessionRenewal`.
RENEWAL_STATE = "session_renewal"
LOGIN_CSRF_COOKIE = "sf_login_csrf"
OPERATOR_ROLES = frozenset({"operator", "admin"})


class LoginRequired(Exception):
    """No valid session: pages redirect to the login form, live fragments answer 401."""

    def __init__(self, next_path: str) -> None:
        super().__init__(next_path)
        self.next_path = next_path


class PageError(Exception):
    """An error shown as a page (404 unknown vehicle, 403 role or CSRF, ...)."""

    def __init__(self, status_code: int, title: str, message: str) -> None:
        super().__init__(message)
        self.status_code = status_code
        self.title = title
        self.message = message


@dataclass(frozen=True)
class PageUser:
    """The logged-in user of a request."""

    username: str
    role: str
    csrf_token: str

    @property
    def may_operate(self) -> bool:
        """Operators and admins change assignments and maintenance; viewers only look."""
        return self.role in OPERATOR_ROLES


def _key(settings: Settings) -> bytes:
    secret = settings.secret_key.get_secret_value().encode()
    return hmac.new(secret, b"smoothfleet dashboard session v1", hashlib.sha256).digest()


def _sign(key: bytes, payload: bytes) -> str:
    return base64.urlsafe_b64encode(hmac.new(key, payload, hashlib.sha256).digest()).decode()


def password_fingerprint(password_hash: str) -> str:
    """A short digest of the stored hash: a new password invalidates old cookies."""
    return hashlib.sha256(password_hash.encode()).hexdigest()[:16]


@dataclass(frozen=True)
class SessionClaims:
    """What a valid cookie says."""

    username: str
    issued_at: float
    nonce: str
    fingerprint: str
    # The user's last activity (a page or a form, not a page's own refresh); cookies issued
    # before the idle limit existed carry none and read their issue as their last activity.
    active_at: float


def to_the_millisecond(moment: float) -> float:
    """A cookie's time: a logout ends the sessions issued before its instant, and a login in
    the same second after it must not read as before it."""
    return math.floor(moment * 1000) / 1000


def new_session(username: str, password_hash: str, now: float) -> SessionClaims:
    """The claims of a session starting now."""
    moment = to_the_millisecond(now)
    return SessionClaims(
        username, moment, secrets.token_hex(16), password_fingerprint(password_hash), moment
    )


def session_cookie(settings: Settings, claims: SessionClaims) -> str:
    """The signed cookie value carrying the claims."""
    payload = json.dumps(
        {
            "u": claims.username,
            "t": claims.issued_at,
            "n": claims.nonce,
            "p": claims.fingerprint,
            "a": claims.active_at,
        },
        separators=(",", ":"),
    ).encode()
    encoded = base64.urlsafe_b64encode(payload).decode()
    return f"{encoded}.{_sign(_key(settings), payload)}"


def same_secret(expected: str, given: str) -> bool:
    """Compare in constant time whatever text a client sent: `hmac.compare_digest` refuses
    non-ASCII strings with TypeError (a 500 for a forged cookie), so both are compared as
    bytes, any lone surrogate included."""
    return hmac.compare_digest(
        expected.encode("utf-8", "surrogatepass"), given.encode("utf-8", "surrogatepass")
    )


def read_session_cookie(settings: Settings, value: str, now: float) -> SessionClaims | None:
    """The claims of a cookie signed by us, neither past its age nor idle too long, else
    None."""
    try:
        encoded, signature = value.split(".", 1)
        payload = base64.urlsafe_b64decode(encoded.encode())
    except (ValueError, TypeError):
        return None
    if not same_secret(_sign(_key(settings), payload), signature):
        return None
    try:
        data = json.loads(payload)
        issued_at = float(data["t"])
        claims = SessionClaims(
            str(data["u"]),
            issued_at,
            str(data["n"]),
            str(data["p"]),
            float(data.get("a", issued_at)),
        )
    except (ValueError, KeyError, TypeError, AttributeError):
        return None
    if not 0 <= now - claims.issued_at <= settings.dashboard_session_max_age_s:
        return None
    if not 0 <= now - claims.active_at <= settings.dashboard_session_idle_s:
        return None
    return claims


def csrf_token(settings: Settings, nonce: str) -> str:
    """The CSRF token of a session (bound to its nonce)."""
    return hmac.new(_key(settings), f"csrf:{nonce}".encode(), hashlib.sha256).hexdigest()


def _settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


def _secure(request: Request) -> bool:
    return request.url.scheme == "https"


def _keep_session(request: Request, response: Response, claims: SessionClaims) -> None:
    """Set the session cookie on this response, kept by the browser until the session's age
    runs out (the idle limit is checked by the server, from the claims)."""
    settings = _settings(request)
    ends_in_s = claims.issued_at + settings.dashboard_session_max_age_s - claims.active_at
    response.set_cookie(
        SESSION_COOKIE,
        session_cookie(settings, claims),
        max_age=max(0, int(ends_in_s)),
        httponly=True,
        samesite="lax",
        secure=_secure(request),
        path="/",
    )


def set_session(request: Request, response: Response, user: OpsUser) -> None:
    """Log the user in on this response."""
    _keep_session(request, response, new_session(user.username, user.password_hash, time.time()))
    response.delete_cookie(LOGIN_CSRF_COOKIE, path="/login")


def clear_session(response: Response) -> None:
    """Log out on this response."""
    response.delete_cookie(SESSION_COOKIE, path="/")


def login_csrf_token(request: Request) -> str:
    """The login form's CSRF token: the browser's current one, or a new one."""
    return request.cookies.get(LOGIN_CSRF_COOKIE) or secrets.token_urlsafe(24)


def remember_login_csrf(request: Request, response: Response, token: str) -> None:
    """Keep the login form's token in a short-lived cookie (double submit)."""
    response.set_cookie(
        LOGIN_CSRF_COOKIE,
        token,
        max_age=3600,
        httponly=True,
        samesite="strict",
        secure=_secure(request),
        path="/login",
    )


def check_login_csrf(request: Request, submitted: str) -> None:
    """Refuse a login form that did not come from our login page."""
    expected = request.cookies.get(LOGIN_CSRF_COOKIE, "")
    if not expected or not same_secret(expected, submitted):
        raise PageError(
            403,
            "Form expired",
            "The login form expired or did not come from this site. Reload the page and log in "
            "again.",
        )


def _next_path(request: Request) -> str:
    path = request.url.path
    if request.url.query:
        path += "?" + request.url.query
    return path


def is_live_refresh(request: Request) -> bool:
    """Whether the request is a refresh the page's script made on its own (no user's act)."""
    name, value = LIVE_REFRESH_HEADER
    return request.headers.get(name) == value


async def current_user(request: Request, session: SessionDep) -> PageUser:
    """The logged-in user; LoginRequired when there is no valid session. A request that is no
    page's own refresh renews the session's time of activity (`SessionRenewal` sends it)."""
    settings = _settings(request)
    value = request.cookies.get(SESSION_COOKIE)
    now = time.time()
    claims = read_session_cookie(settings, value, now) if value else None
    if claims is None:
        raise LoginRequired(_next_path(request))
    user = await session.scalar(select(OpsUser).where(OpsUser.username == claims.username))
    if user is None or password_fingerprint(user.password_hash) != claims.fingerprint:
        raise LoginRequired(_next_path(request))
    ended = user.sessions_valid_from
    if ended is not None and claims.issued_at < ended.timestamp():
        raise LoginRequired(_next_path(request))
    if not is_live_refresh(request):
        renewal = Response()
        _keep_session(request, renewal, replace(claims, active_at=to_the_millisecond(now)))
        setattr(request.state, RENEWAL_STATE, renewal.headers["set-cookie"].encode("latin-1"))
    return PageUser(user.username, user.role, csrf_token(settings, claims.nonce))


UserDep = Annotated[PageUser, Depends(current_user)]


def navigating_user(request: Request) -> PageUser | None:
    """Who the session cookie names, for the navigation of an error page only (no database:
    the page may be an error of the database itself); never for deciding what may be done."""
    value = request.cookies.get(SESSION_COOKIE)
    settings = _settings(request)
    claims = read_session_cookie(settings, value, time.time()) if value else None
    if claims is None:
        return None
    return PageUser(claims.username, "", csrf_token(settings, claims.nonce))


def check_form(user: PageUser, submitted_token: str, *, needs_operator: bool) -> None:
    """Refuse a form without this session's CSRF token, or an action beyond the user's role."""
    if not same_secret(user.csrf_token, submitted_token):
        raise PageError(
            403,
            "Form expired",
            "This form expired or did not come from this site. Reload the page and try again.",
        )
    if needs_operator and not user.may_operate:
        raise PageError(
            403,
            "Not allowed",
            f"Your role is {user.role}: only operators and admins can change vehicles. Ask an "
            "admin for the operator role.",
        )


def safe_next(path: str | None) -> str:
    """Where to go after login: a local path only (never another site)."""
    if path and path.startswith("/") and not path.startswith("//") and "\\" not in path:
        return path
    return "/fleet"


class SessionRenewal:
    """ASGI middleware adding the renewed session cookie `current_user` left on a request to
    its response, unless the response sets the session cookie itself (a login, a logout:
    their own cookie must be the browser's last word)."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        # the request's state, shared with every layer below (Request.state reads this dict)
        state = scope.setdefault("state", {})

        async def send_renewed(message: Message) -> None:
            renewal: bytes | None = state.get(RENEWAL_STATE)
            if message["type"] == "http.response.start" and renewal is not None:
                headers = list(message.get("headers", []))
                own = SESSION_COOKIE.encode() + b"="
                if not any(k == b"set-cookie" and v.startswith(own) for k, v in headers):
                    message = {**message, "headers": [*headers, (b"set-cookie", renewal)]}
            await send(message)

        await self.app(scope, receive, send_renewed)
