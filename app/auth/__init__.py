"""Bearer-token authentication and roles, as FastAPI dependencies.

Use `AuthDep` for "any valid token" and `allow(...)` for a set of roles, e.g.
`Annotated[Principal, Depends(allow("operator", "admin"))]`.
"""

from app.auth.dependencies import (
    CHALLENGE,
    PING_WRITER_ROLES,
    AuthDep,
    FeedWriterDep,
    OperatorDep,
    PingWriterDep,
    ViewerDep,
    allow,
    authenticate,
    bearer_scheme,
)
from app.auth.tokens import Principal, TokenCache, bearer_token, token_cache_for

__all__ = [
    "CHALLENGE",
    "PING_WRITER_ROLES",
    "AuthDep",
    "FeedWriterDep",
    "OperatorDep",
    "PingWriterDep",
    "Principal",
    "TokenCache",
    "ViewerDep",
    "allow",
    "authenticate",
    "bearer_scheme",
    "bearer_token",
    "token_cache_for",
]
