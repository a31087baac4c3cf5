"""A vehicle's config carries a version, and its status reports the version it runs.

Revision ID: 0006
Revises: 0005
Create Date: 2026-11-30 13:10:00+00:00

Every change of what a car should run (assignment, maintenance) bumps
`dim_vehicle.config_version`; the agent echoes the version it has applied in its status reports
(`fact_vehicle_status.config_version`), so operators see when a change has reached the car.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0006"
down_revision: str | None = "0005"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column(
        "dim_vehicle",
        sa.Column("config_version", sa.Integer(), server_default=sa.text("1"), nullable=False),
    )
    op.add_column("fact_vehicle_status", sa.Column("config_version", sa.Integer(), nullable=True))


def downgrade() -> None:
    op.drop_column("fact_vehicle_status", "config_version")
    op.drop_column("dim_vehicle", "config_version")
