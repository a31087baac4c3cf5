"""An assignment's change row keeps the controller's parameters, the policy among them.

Revision ID: 0016
Revises: 0015
Create Date: 2026-12-04 23:55:00+00:00

`fact_vehicle_change` kept the controller's name only: swapping a car from one rl_acc policy
to another left two identical rows, so nobody could tell later who put which policy on which
car, or when (policy audit). `controller_params` holds what the assignment set (JSONB, as
`dim_vehicle.controller_params`; `policy_sha256` names the policy). Rows written before this
migration, and maintenance rows, have none.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0016"
down_revision: str | None = "0015"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.add_column(
        "fact_vehicle_change",
        sa.Column("controller_params", postgresql.JSONB(astext_type=sa.Text()), nullable=True),
    )


def downgrade() -> None:
    op.drop_column("fact_vehicle_change", "controller_params")
