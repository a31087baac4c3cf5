"""Issue API tokens straight into a test database (as `smoothfleet tokens create` does)."""

from __future__ import annotations

from sqlalchemy import Engine

from app.core.db import session_scope
from app.core.security import TokenRole, issue_token


def issue(engine: Engine, role: TokenRole, vehicle_id: str | None = None) -> str:
    """A fresh token of the role (bound to `vehicle_id` for a vehicle token)."""
    with session_scope(engine) as session:
        return issue_token(session, role, vehicle_id=vehicle_id, name=f"test {role}")


def bearer(token: str) -> dict[str, str]:
    """The Authorization header carrying the token."""
    return {"Authorization": f"Bearer {token}"}
