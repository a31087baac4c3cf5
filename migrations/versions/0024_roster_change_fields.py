"""A roster change row keeps what the import changed, before and after.

Revision ID: 0024
Revises: 0023
Create Date: 2026-12-05 20:00:00+00:00

A roster row (0023) kept the lane, route and controller the imported row set: an import that
moved a car from lane 1 to 3 read "lane 3" on the vehicle page, and one that changed only the
controller's parameters, the corridor or the actuation read as if it had changed nothing.
`roster_changed` holds each roster field the import changed as `[before, after]`. Rows written
before it have none: what they changed was not kept.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0024"
down_revision: str | None = "0023"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column(
        "fact_vehicle_change",
        sa.Column("roster_changed", postgresql.JSONB(astext_type=sa.Text()), nullable=True),
    )


def downgrade() -> None:
    op.drop_column("fact_vehicle_change", "roster_changed")
