"""Status reports age out with the pings: an index on their time for the retention pass.

Revision ID: 0009
Revises: 0008
Create Date: 2026-12-02 16:50:00+00:00

`fact_vehicle_status` takes a report from every car every ~10 s (about 860,000 rows a day for
100 cars) and kept them for ever. The maintenance pass now deletes those older than
SMOOTHFLEET_PING_RETENTION_DAYS, the window a report is accepted in at all
(app/maintenance.py). Its primary key leads with the vehicle, so without an index on `ts` that
hourly delete would read the whole table.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0009"
down_revision: str | None = "0008"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


def upgrade() -> None:
    op.create_index("ix_fact_vehicle_status_ts", "fact_vehicle_status", ["ts"])


def downgrade() -> None:
    op.drop_index("ix_fact_vehicle_status_ts", table_name="fact_vehicle_status")
