"""A dashboard user's sessions issued before `sessions_valid_from` are over.

Revision ID: 0018
Revises: 0017
Create Date: 2026-12-05 14:20:00+00:00

The session cookie is signed and stateless: logging out only asked the browser to forget it,
and a copy (a shared computer, a proxy's log) stayed valid for the rest of its 12 h (security
audit). Logging out now sets `sessions_valid_from` to that moment, and a cookie issued before it
is refused: every session of the user ends, on every device. NULL: none ended so.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0018"
down_revision: str | None = "0017"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column(
        "ops_user",
        sa.Column("sessions_valid_from", sa.DateTime(timezone=True), nullable=True),
    )


def downgrade() -> None:
    op.drop_column("ops_user", "sessions_valid_from")
