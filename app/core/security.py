"""Bearer tokens: random, shown once, stored as SHA-256 only."""

from __future__ import annotations

import hashlib
import secrets
from typing import Literal

from sqlalchemy import insert
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
