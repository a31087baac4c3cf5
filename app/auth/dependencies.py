"""FastAPI dependencies: 401 without a valid bearer token, 403 for a role that may not act.

Roles (docs/interfaces.md): `vehicle` (bound to one vehicle_id), `feed` (third-party data),
ops `viewer` < `operator` < `admin`. What each endpoint allows is stated where it is declared.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from app.auth.tokens import Principal, token_cache_for, token_rate_limiter
from app.core.ratelimit import retry_after_header
from app.core.security import TokenRole

bearer_scheme = HTTPBearer(auto_error=False, description="A smoothfleet API token (sf_...).")

CHALLENGE = {"WWW-Authenticate": "Bearer"}


async def authenticate(
    request: Request,
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer_scheme)],
) -> Principal:
    """The caller's principal; 401 when the token is missing, malformed, unknown or revoked."""
    if credentials is None:
        raise HTTPException(401, "missing bearer token (Authorization: Bearer <token>)", CHALLENGE)
    principal = await token_cache_for(request.app.state).principal(credentials.credentials)
    if principal is None:
        raise HTTPException(401, "invalid or revoked token", CHALLENGE)
    wait_s = token_rate_limiter(request.app.state).wait_s(principal.token_id)
    if wait_s:
        raise HTTPException(429, "too many requests for this token", retry_after_header(wait_s))
    # Kept on the request for what runs later (access logs).
    request.state.principal = principal
    return principal


def allow(*roles: TokenRole) -> Callable[..., Awaitable[Principal]]:
    """A dependency admitting only the given roles (403 for any other valid token)."""
    allowed = frozenset(roles)
    needed = " or ".join(roles)

    async def admitted(principal: Annotated[Principal, Depends(authenticate)]) -> Principal:
        if principal.role not in allowed:
            raise HTTPException(403, f"{principal.token_words} may not do this (needs {needed})")
        return principal

    return admitted


AuthDep = Annotated[Principal, Depends(authenticate)]
"""Any valid token."""
ViewerDep = Annotated[Principal, Depends(allow("viewer", "operator", "admin"))]
"""Any ops token (read-only operations)."""
OperatorDep = Annotated[Principal, Depends(allow("operator", "admin"))]
"""Operators and admins (changing assignments)."""
PING_WRITER_ROLES: tuple[TokenRole, ...] = ("vehicle", "operator", "admin")
PingWriterDep = Annotated[Principal, Depends(allow(*PING_WRITER_ROLES))]
"""Who may post pings and status reports (a vehicle token only for its own vehicle)."""
FeedWriterDep = Annotated[Principal, Depends(allow("feed", "admin"))]
"""Who may post third-party feed data."""
