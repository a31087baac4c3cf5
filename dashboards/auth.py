"""Dashboard sessions: a signed cookie after login, CSRF tokens for every form, role checks.

The cookie holds the username, when it was issued, a random session nonce and a fingerprint of
the user's password hash, signed with HMAC-SHA256 under a key derived from
SMOOTHFLEET_SECRET_KEY. Every request reloads the user, so a changed role applies at once and a
changed password (new fingerprint) ends every old session. Forms carry a CSRF token derived from
the session nonce; the login form, which has no session yet, uses a double-submit cookie.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import json
import math
import secrets
import time
from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request, Response
from sqlalchemy import select

from app.core.config import Settings
from app.core.sessions import SessionDep
from app.models import OpsUser

SESSION_COOKIE = "sf_session"
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


def session_cookie(settings: Settings, username: str, password_hash: str, now: float) -> str:
    """A signed session cookie value for the user."""
    payload = json.dumps(
        {
            "u": username,
            # to the millisecond: a logout ends the sessions issued before its instant, and a
            # login in the same second after it must not read as before it
            "t": math.floor(now * 1000) / 1000,
            "n": secrets.token_hex(16),
            "p": password_fingerprint(password_hash),
        },
        separators=(",", ":"),
    ).encode()
    encoded = base64.urlsafe_b64encode(payload).decode()
    return f"{encoded}.{_sign(_key(settings), payload)}"


@dataclass(frozen=True)
class SessionClaims:
    """What a valid cookie says."""

    username: str
    issued_at: float
    nonce: str
    fingerprint: str


def same_secret(expected: str, given: str) -> bool:
    """Compare in constant time whatever text a client sent: `hmac.compare_digest` refuses
    non-ASCII strings with TypeError (a 500 for a forged cookie), so both are compared as
    bytes, any lone surrogate included."""
    return hmac.compare_digest(
        expected.encode("utf-8", "surrogatepass"), given.encode("utf-8", "surrogatepass")
    )


def read_session_cookie(settings: Settings, value: str, now: float) -> SessionClaims | None:
    """The claims of a cookie signed by us and not expired, else None."""
    try:
        encoded, signature = value.split(".", 1)
        payload = base64.urlsafe_b64decode(encoded.encode())
    except (ValueError, TypeError):
        return None
    if not same_secret(_sign(_key(settings), payload), signature):
        return None
    try:
        data = json.loads(payload)
        claims = SessionClaims(str(data["u"]), float(data["t"]), str(data["n"]), str(data["p"]))
    except (ValueError, KeyError, TypeError):
        return None
    if not 0 <= now - claims.issued_at <= settings.dashboard_session_max_age_s:
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


def set_session(request: Request, response: Response, user: OpsUser) -> None:
    """Log the user in on this response."""
    settings = _settings(request)
    response.set_cookie(
        SESSION_COOKIE,
        session_cookie(settings, user.username, user.password_hash, time.time()),
        max_age=int(settings.dashboard_session_max_age_s),
        httponly=True,
        samesite="lax",
        secure=_secure(request),
        path="/",
    )
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


async def current_user(request: Request, session: SessionDep) -> PageUser:
    """The logged-in user; LoginRequired when there is no valid session."""
    settings = _settings(request)
    value = request.cookies.get(SESSION_COOKIE)
    claims = read_session_cookie(settings, value, time.time()) if value else None
    if claims is None:
        raise LoginRequired(_next_path(request))
    user = await session.scalar(select(OpsUser).where(OpsUser.username == claims.username))
    if user is None or password_fingerprint(user.password_hash) != claims.fingerprint:
        raise LoginRequired(_next_path(request))
    ended = user.sessions_valid_from
    if ended is not None and claims.issued_at < ended.timestamp():
        raise LoginRequired(_next_path(request))
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
