"""inrix_latency's mean speed is the corridor's space-mean speed, not the segments' plain mean.

Revision ID: 0010
Revises: 0009
Create Date: 2026-12-03 09:30:00+00:00

`mean_speed_mps` averaged the segments' speeds with equal weight, so a 25 m segment counted as
much as a 1.25 km one, and a plain mean of speeds overstates the speed of a road in congestion
(one segment at 30 m/s and one at 5 m/s read 17.5 m/s; driving them takes as long as 5.1 m/s
would). It is now what a traffic scientist means by a road's mean speed: its length over the
time to drive it, sum(L) / sum(L / v), over the open segments that report a speed; closed
segments stay counted in `closed_segments`.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0010"
down_revision: str | None = "0009"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COMMENT = """
COMMENT ON VIEW analytics.inrix_latency IS
    'One row per corridor per INRIX snapshot (measured_at): segments and latency (s) until '
    'received.';
"""

# One definition, two means: the columns and grouping are 0002's.
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
    {join}
    GROUP BY e.corridor_id, e.measured_at;
"""

PLAIN_MEAN = VIEW.format(mean="avg(e.speed_mps)", join="")

# The space-mean speed of the open segments with a speed: their length over their travel time.
OPEN = "FILTER (WHERE NOT e.is_closed AND e.speed_mps > 0)"
SPACE_MEAN = VIEW.format(
    mean=f"sum(s.length_m) {OPEN} / sum(s.length_m / e.speed_mps) {OPEN}",
    join="JOIN dim_inrix_segment s ON s.xd_code = e.xd_code",
)


def upgrade() -> None:
    op.execute(SPACE_MEAN)
    op.execute(COMMENT)


def downgrade() -> None:
    op.execute(PLAIN_MEAN)
    op.execute(COMMENT)
