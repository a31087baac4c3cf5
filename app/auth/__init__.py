"""Bearer-token authentication and roles, as FastAPI dependencies.

Use `AuthDep` for "any valid token" and `allow(...)` for a set of roles, e.g.
`Annotated[Principal, Depends(allow("operator", "admin"))]`.
"""

from app.auth.dependencies import (
    AdminDep,
    AuthDep,
    FeedWriterDep,
    OperatorDep,
    PingWriterDep,
    ViewerDep,
    allow,
    authenticate,
)
from app.auth.tokens import Principal, TokenCache

__all__ = [
    "AdminDep",
    "AuthDep",
    "FeedWriterDep",
    "OperatorDep",
    "PingWriterDep",
    "Principal",
    "TokenCache",
    "ViewerDep",
    "allow",
    "authenticate",
]
