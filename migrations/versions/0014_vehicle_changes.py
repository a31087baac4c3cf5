"""Who changed a vehicle's assignment or maintenance, and when.

Revision ID: 0014
Revises: 0013
Create Date: 2026-12-04 21:20:00+00:00

An operator taking a car out of deployment (maintenance) or giving it another lane, route or
controller left no record of who did it or when: the service logged a line that no handler
wrote, and `dim_vehicle` holds only the state now. `fact_vehicle_change` keeps one row per
change made through the API or the dashboard, keyed by the vehicle and the config version the
change produced (every such change raises it by one), with who made it (a dashboard user, or
an API token by id), when (the database clock) and what it set. The vehicle page lists them.
Changes made before this migration, and by `smoothfleet vehicles import` or the seed, which
are roster loads rather than an operator's decision on one car, have no row.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0014"
down_revision: str | None = "0013"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_table(
        "fact_vehicle_change",
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("config_version", sa.Integer(), nullable=False),
        sa.Column(
            "changed_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column("changed_by", sa.Text(), nullable=False),
        sa.Column("change", sa.Text(), nullable=False),
        sa.Column("lane", sa.SmallInteger(), nullable=True),
        sa.Column("route", sa.Text(), nullable=True),
        sa.Column("controller_name", sa.Text(), nullable=True),
        sa.Column("in_maintenance", sa.Boolean(), nullable=True),
        sa.Column("note", sa.Text(), nullable=True),
        sa.CheckConstraint(
            "change IN ('assignment', 'maintenance')",
            name=op.f("ck_fact_vehicle_change_change_kind"),
        ),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_fact_vehicle_change_vehicle_id_dim_vehicle"),
        ),
        sa.PrimaryKeyConstraint(
            "vehicle_id", "config_version", name=op.f("pk_fact_vehicle_change")
        ),
        comment="One row per operator's change to a vehicle (the config version it produced).",
    )


def downgrade() -> None:
    op.drop_table("fact_vehicle_change")
