"""Bearer tokens: random, shown once, stored as SHA-256 only."""

from __future__ import annotations

import hashlib
import secrets
from collections.abc import Sequence
from typing import Literal

from sqlalchemy import func, insert, select, update
from sqlalchemy.orm import Session

from app.models import ApiToken

TokenRole = Literal["vehicle", "feed", "viewer", "operator", "admin"]
TOKEN_ROLES: tuple[TokenRole, ...] = ("vehicle", "feed", "viewer", "operator", "admin")
OPS_ROLES = ("viewer", "operator", "admin")
TOKEN_PREFIX = "sf_"


def new_token() -> str:
    """A fresh bearer token: 256 random bits, URL-safe."""
    return TOKEN_PREFIX + secrets.token_urlsafe(32)


def hash_token(token: str) -> str:
    """What the database keeps of a token (hex SHA-256)."""
    return hashlib.sha256(token.encode()).hexdigest()


def issue_token(
    session: Session, role: TokenRole, *, vehicle_id: str | None = None, name: str = ""
) -> str:
    """Store a new token's hash and return the token itself (the only time it is known)."""
    if (role == "vehicle") != (vehicle_id is not None):
        raise ValueError("a vehicle token needs --vehicle, and only a vehicle token takes one")
    token = new_token()
    kind = role if role in ("vehicle", "feed") else "ops"
    session.execute(
        insert(ApiToken).values(
            kind=kind,
            role=role if kind == "ops" else None,
            vehicle_id=vehicle_id,
            name=name,
            token_hash=hash_token(token),
        )
    )
    return token


def revoke_tokens(
    session: Session,
    *,
    token_id: int | None = None,
    vehicle_id: str | None = None,
    token: str | None = None,
) -> list[int]:
    """Mark matching live tokens revoked; returns their ids (servers refuse them within the
    token cache's lifetime, `SMOOTHFLEET_TOKEN_CACHE_TTL_S`)."""
    chosen = [value for value in (token_id, vehicle_id, token) if value is not None]
    if len(chosen) != 1:
        raise ValueError("name exactly one of: a token id, a vehicle, a token")
    statement = update(ApiToken).where(ApiToken.revoked_at.is_(None))
    if token_id is not None:
        statement = statement.where(ApiToken.token_id == token_id)
    elif vehicle_id is not None:
        statement = statement.where(ApiToken.vehicle_id == vehicle_id)
    else:
        assert token is not None
        statement = statement.where(ApiToken.token_hash == hash_token(token))
    revoked = session.execute(
        statement.values(revoked_at=func.now()).returning(ApiToken.token_id)
    ).scalars()
    return sorted(revoked)


def list_tokens(session: Session) -> Sequence[ApiToken]:
    """Every token ever issued (hashes only), newest first."""
    return session.scalars(select(ApiToken).order_by(ApiToken.token_id.desc())).all()
