"""A status report says why the agent commands its car or leaves it to the stock ACC.

Revision ID: 0008
Revises: 0007
Create Date: 2026-12-02 14:00:00+00:00

`fact_vehicle_status.engage_reason` holds the agent's engage reason at the report ("engaged",
"no fresh plan", "controller failed", "button presses not confirmed by the car", ...), so an
operator sees beside each car why it is not engaged, and an analyst can count the causes of
hand-backs in SQL. Null in the reports of agents that predate it.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0008"
down_revision: str | None = "0007"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("fact_vehicle_status", sa.Column("engage_reason", sa.Text(), nullable=True))


def downgrade() -> None:
    op.drop_column("fact_vehicle_status", "engage_reason")
