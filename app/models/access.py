"""Who may call the API and the dashboard: bearer tokens and ops users (secrets stored hashed)."""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    BigInteger,
    CheckConstraint,
    DateTime,
    ForeignKey,
    Identity,
    Integer,
    Text,
    text,
)
from sqlalchemy.orm import Mapped, mapped_column

from app.models.base import Base, created_at_column


class ApiToken(Base):
    """A bearer token: vehicle (bound to one vehicle), feed (third-party ingest) or ops (role).

    Only the SHA-256 of the token is stored: tokens are 256-bit random strings, so a fast hash is
    enough, and lookups by hash need no per-row salt.
    """

    __tablename__ = "api_token"
    __table_args__ = (
        CheckConstraint("kind IN ('vehicle', 'feed', 'ops')", name="token_kind"),
        CheckConstraint(
            "role IS NULL OR role IN ('viewer', 'operator', 'admin')", name="role_kind"
        ),
        CheckConstraint("(kind = 'vehicle') = (vehicle_id IS NOT NULL)", name="vehicle_binding"),
        CheckConstraint("(kind = 'ops') = (role IS NOT NULL)", name="ops_role"),
        {"comment": "One row per issued bearer token; token_hash = sha256(token) hex."},
    )

    token_id: Mapped[int] = mapped_column(BigInteger, Identity(), primary_key=True)
    kind: Mapped[str] = mapped_column(Text)
    role: Mapped[str | None] = mapped_column(Text)
    vehicle_id: Mapped[str | None] = mapped_column(
        ForeignKey("dim_vehicle.vehicle_id", ondelete="CASCADE"), index=True
    )
    name: Mapped[str] = mapped_column(Text, server_default=text("''"))
    token_hash: Mapped[str] = mapped_column(Text, unique=True)
    created_at: Mapped[datetime] = created_at_column()
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    last_used_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))


class OpsUser(Base):
    """A person who logs into the dashboard (viewer, operator or admin)."""

    __tablename__ = "ops_user"
    __table_args__ = (
        CheckConstraint("role IN ('viewer', 'operator', 'admin')", name="role_kind"),
        {"comment": "One row per dashboard user; password_hash is a salted scrypt hash."},
    )

    username: Mapped[str] = mapped_column(Text, primary_key=True)
    password_hash: Mapped[str] = mapped_column(Text)
    role: Mapped[str] = mapped_column(Text)
    failed_logins: Mapped[int] = mapped_column(Integer, server_default=text("0"))
    last_failed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    last_login_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    # Sessions issued before this are over (set at logout: every session of the user ends).
    sessions_valid_from: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    created_at: Mapped[datetime] = created_at_column()


class OpsLoginFailure(Base):
    """Failed logins of one account from one client since that client's last success.

    The wait between attempts is counted per (account, client): counted per account alone, a
    stranger's one wrong guess every five minutes kept the account's owner out for good.
    """

    __tablename__ = "ops_login_failure"
    __table_args__ = (
        {"comment": "Failed dashboard logins per (user, client address) since its last success."},
    )

    username: Mapped[str] = mapped_column(
        ForeignKey("ops_user.username", ondelete="CASCADE"), primary_key=True
    )
    # the client's key (`app.users.client_key`): an IPv4 address or an IPv6 /64, never the
    # IPv6 address it used, whose rotation within the /64 met a fresh allowance each time
    client_address: Mapped[str] = mapped_column(Text, primary_key=True)
    failures: Mapped[int] = mapped_column(Integer)
    last_failed_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
