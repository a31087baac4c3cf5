"""A roster load that changes a vehicle is kept in fact_vehicle_change, as an operator's is.

Revision ID: 0023
Revises: 0022
Create Date: 2026-12-05 19:00:00+00:00

`smoothfleet vehicles import` (and `vehicles add` of an existing id) bumps the config version
of every vehicle whose row it changes, as an assignment does, but wrote no change row: the
vehicle's history skipped that version, and a controller or lane changed by a re-import was
recorded nowhere (dim_vehicle_assignment keeps corridor, route and lane only). Such a change
is now kept with `change = 'roster'`, who made it naming the command and the file.
Downgrading deletes those rows: the older check admits assignment and maintenance only.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0023"
down_revision: str | None = "0022"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

CONSTRAINT = "ck_fact_vehicle_change_change_kind"


def upgrade() -> None:
    op.drop_constraint(op.f(CONSTRAINT), "fact_vehicle_change", type_="check")
    op.create_check_constraint(
        op.f(CONSTRAINT), "fact_vehicle_change", "change IN ('assignment', 'maintenance', 'roster')"
    )


def downgrade() -> None:
    op.execute("DELETE FROM fact_vehicle_change WHERE change = 'roster'")
    op.drop_constraint(op.f(CONSTRAINT), "fact_vehicle_change", type_="check")
    op.create_check_constraint(
        op.f(CONSTRAINT), "fact_vehicle_change", "change IN ('assignment', 'maintenance')"
    )
