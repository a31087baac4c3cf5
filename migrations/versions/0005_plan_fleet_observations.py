"""Each plan row keeps the fleet observation the plan read for its lane and sub-segment.

Revision ID: 0005
Revises: 0004
Create Date: 2026-11-30 12:45:00+00:00

A plan must replay bit for bit from what it stored. Re-reading the ping window later cannot do
that: pings of the window keep arriving after the cycle read it (agents upload their spools
late; a request in flight commits just after the read), and PostgreSQL's float sums depend on
the order rows are aggregated. The pooled fleet observation the cycle used (mean speed of the
window's pings in that lane and sub-segment, in double precision, and their count) is small
(one value per plan cell) and is now stored beside the target it produced.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0005"
down_revision: str | None = "0004"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column("fact_speed_planner", sa.Column("fleet_speed_mps", sa.Float(), nullable=True))
    op.add_column("fact_speed_planner", sa.Column("fleet_ping_count", sa.Integer(), nullable=True))


def downgrade() -> None:
    op.drop_column("fact_speed_planner", "fleet_ping_count")
    op.drop_column("fact_speed_planner", "fleet_speed_mps")
