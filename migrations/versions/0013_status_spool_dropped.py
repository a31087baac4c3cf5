"""A status report says how many pings the car's spool dropped unsent.

Revision ID: 0013
Revises: 0012
Create Date: 2026-12-04 21:10:00+00:00

The spool on the car is bounded: past its row limit the oldest pings are dropped, so a car
offline for days cannot fill its disk. How many it dropped was counted only in the spool's own
SQLite file; no log line and no report carried it, so pings lost that way were lost silently.
`fact_vehicle_status.spool_dropped` holds the spool's running total at each report (since the
spool file was made), so an operator sees it beside the backlog and an analyst can count the
pings a car never delivered. Null in the reports of agents that predate it.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0013"
down_revision: str | None = "0012"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("fact_vehicle_status", sa.Column("spool_dropped", sa.Integer(), nullable=True))


def downgrade() -> None:
    op.drop_column("fact_vehicle_status", "spool_dropped")
