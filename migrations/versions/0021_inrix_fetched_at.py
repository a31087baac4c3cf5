"""An INRIX reading keeps when its answer was fetched; the latency reads it.

Revision ID: 0021
Revises: 0020
Create Date: 2026-12-05 16:30:00+00:00

`received_at` is when the server stored a reading. The poller keeps the minutes it fetched
while the database was away and stores them later, and a replay stores a recording's minutes
long after they were fetched: `analytics.inrix_latency` counted that delay as the provider's
(an audit). `fetched_at` is when the poller (or the recording) got the provider's answer; NULL
for readings stored as they arrived (the feed endpoint, and every row before this migration).
The view's latency reads `fetched_at` where it is known, `received_at` otherwise.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op

revision: str = "0021"
down_revision: str | None = "0020"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COMMENT = """
COMMENT ON VIEW analytics.inrix_latency IS
    'One row per corridor per INRIX snapshot (measured_at): segments and latency (s) until '
    '{until}.';
"""

# 0020's view; the first arrival is the fetch where known.
VIEW = """
-- INRIX speeds arrive minutes after the time they describe (paper: the planner predicts past
-- this latency). One provider snapshot = all segments with the same measured_at.
CREATE OR REPLACE VIEW analytics.inrix_latency AS
    SELECT e.corridor_id,
           e.measured_at,
           count(*) AS segments,
           count(*) FILTER (WHERE e.score = 30) AS realtime_segments,
           count(*) FILTER (WHERE e.is_closed) AS closed_segments,
           min({arrival}) AS received_at,
           extract(epoch FROM min({arrival}) - e.measured_at)::double precision AS latency_s,
           (CASE WHEN bool_or(NOT e.is_closed AND e.speed_mps = 0) THEN 0.0
                 ELSE sum(s.length_m) FILTER (WHERE NOT e.is_closed AND e.speed_mps > 0)
                      / sum(s.length_m / e.speed_mps)
                        FILTER (WHERE NOT e.is_closed AND e.speed_mps > 0)
            END)::double precision AS mean_speed_mps
    FROM fact_inrix_estimate e
    JOIN dim_inrix_segment s ON s.xd_code = e.xd_code
    GROUP BY e.corridor_id, e.measured_at;
"""


def upgrade() -> None:
    op.add_column(
        "fact_inrix_estimate",
        sa.Column("fetched_at", sa.DateTime(timezone=True), nullable=True),
    )
    op.execute(VIEW.format(arrival="coalesce(e.fetched_at, e.received_at)"))
    op.execute(COMMENT.format(until="fetched (received, where the fetch time is not known)"))


def downgrade() -> None:
    op.execute(VIEW.format(arrival="e.received_at"))
    op.execute(COMMENT.format(until="received"))
    op.drop_column("fact_inrix_estimate", "fetched_at")
