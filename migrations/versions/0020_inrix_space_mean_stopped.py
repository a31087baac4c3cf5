"""inrix_latency's space-mean speed is 0 when an open segment reports traffic standing.

Revision ID: 0020
Revises: 0019
Create Date: 2026-12-05 16:20:00+00:00

Migration 0010 made `mean_speed_mps` the corridor's length over the time to drive it,
sum(L) / sum(L / v), over the open segments with a speed above 0: a segment reading 0 m/s was
left out, so a corridor with standing traffic on one segment read as fast as its moving ones
(an audit). Standing traffic takes unbounded time to drive, and the space-mean speed of a road
holding it is 0. Closed segments and segments without a speed stay out, as before.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0020"
down_revision: str | None = "0019"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COMMENT = """
COMMENT ON VIEW analytics.inrix_latency IS
    'One row per corridor per INRIX snapshot (measured_at): segments and latency (s) until '
    'received.';
"""

# 0010's view, its mean given the standing segments' 0.
VIEW = """
-- INRIX speeds arrive minutes after the time they describe (paper: the planner predicts past
-- this latency). One provider snapshot = all segments with the same measured_at.
CREATE OR REPLACE VIEW analytics.inrix_latency AS
    SELECT e.corridor_id,
           e.measured_at,
           count(*) AS segments,
           count(*) FILTER (WHERE e.score = 30) AS realtime_segments,
           count(*) FILTER (WHERE e.is_closed) AS closed_segments,
           min(e.received_at) AS received_at,
           extract(epoch FROM min(e.received_at) - e.measured_at)::double precision AS latency_s,
           ({mean})::double precision AS mean_speed_mps
    FROM fact_inrix_estimate e
    JOIN dim_inrix_segment s ON s.xd_code = e.xd_code
    GROUP BY e.corridor_id, e.measured_at;
"""

MOVING = "FILTER (WHERE NOT e.is_closed AND e.speed_mps > 0)"
STANDING = "bool_or(NOT e.is_closed AND e.speed_mps = 0)"
SPACE_MEAN_0010 = f"sum(s.length_m) {MOVING} / sum(s.length_m / e.speed_mps) {MOVING}"


def upgrade() -> None:
    op.execute(VIEW.format(mean=f"CASE WHEN {STANDING} THEN 0.0 ELSE {SPACE_MEAN_0010} END"))
    op.execute(COMMENT)


def downgrade() -> None:
    op.execute(VIEW.format(mean=SPACE_MEAN_0010))
    op.execute(COMMENT)
