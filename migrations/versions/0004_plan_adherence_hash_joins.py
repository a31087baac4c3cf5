"""plan_adherence by equality joins on the ping's sub-segment, so a day of pings hash-joins.

Revision ID: 0004
Revises: 0003
Create Date: 2026-11-23 11:20:00+00:00

0003 looked each ping's target up by primary key (LATERAL ... LIMIT 1): steady on partitions
without statistics, but ~10 us a ping, 10 s for a 100-car, two-hour deployment (720,000 pings).
Here the sub-segment is computed from x_m (binary search over the corridor's segment starts) and
every join is an equality, which PostgreSQL runs as hash joins: ~2 s for the same day on the
loaded shared machine. It relies on the ping partitions having statistics, which autovacuum
gathers within a minute of the first rows.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0004"
down_revision: str | None = "0003"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

COMMENT = """
COMMENT ON VIEW analytics.plan_adherence IS
    'One row per ping that follows a plan: its speed against the plan''s target where it was.';
"""

EQUALITY_JOINS = """
-- A ping that names the plan it follows is compared with that plan's target for the lane it
-- drove in (its reported lane, else its assigned lane) and the sub-segment holding its x_m,
-- found by binary search over the corridor's segment starts (width_bucket).
CREATE OR REPLACE VIEW analytics.plan_adherence AS
    WITH grid AS (
        SELECT corridor_id,
               array_agg(start_x_m ORDER BY start_x_m) AS starts,
               array_agg(i24_segment_id ORDER BY start_x_m) AS segment_ids
        FROM dim_i24_segment
        GROUP BY corridor_id
    ),
    located AS (
        SELECT p.vehicle_id,
               p.ts,
               p.plan_id,
               p.x_m,
               p.speed_mps,
               p.is_controller_engaged,
               v.corridor_id,
               coalesce(p.lane, v.assigned_lane) AS lane,
               g.segment_ids[width_bucket(p.x_m::double precision, g.starts)] AS i24_segment_id
        FROM fact_vehicle_ping p
        JOIN dim_vehicle v ON v.vehicle_id = p.vehicle_id
        JOIN grid g ON g.corridor_id = v.corridor_id
        WHERE p.plan_id IS NOT NULL AND p.x_m IS NOT NULL
    )
    SELECT l.vehicle_id,
           l.ts,
           l.plan_id,
           sp.lane,
           s.i24_segment_id,
           l.x_m::double precision AS x_m,
           c.postmile_at_start + l.x_m::double precision / 1609.344 AS postmile,
           l.speed_mps::double precision AS speed_mps,
           sp.target_speed_mps::double precision AS target_speed_mps,
           (l.speed_mps - sp.target_speed_mps)::double precision AS speed_error_mps,
           sp.is_buffer,
           l.is_controller_engaged,
           extract(epoch FROM l.ts - r.published_at)::double precision AS plan_age_s
    FROM located l
    JOIN dim_corridor c ON c.corridor_id = l.corridor_id
    JOIN dim_i24_segment s ON s.i24_segment_id = l.i24_segment_id AND l.x_m < s.end_x_m
    JOIN plan_run r ON r.corridor_id = l.corridor_id AND r.plan_id = l.plan_id
    JOIN fact_speed_planner sp
      ON sp.corridor_id = l.corridor_id
     AND sp.plan_id = l.plan_id
     AND sp.lane = l.lane
     AND sp.i24_segment_id = l.i24_segment_id;
"""

KEY_LOOKUPS = """
CREATE OR REPLACE VIEW analytics.plan_adherence AS
    WITH grid AS (
        SELECT corridor_id,
               array_agg(start_x_m ORDER BY start_x_m) AS starts,
               array_agg(i24_segment_id ORDER BY start_x_m) AS segment_ids
        FROM dim_i24_segment
        GROUP BY corridor_id
    )
    SELECT p.vehicle_id,
           p.ts,
           p.plan_id,
           sp.lane,
           s.i24_segment_id,
           p.x_m::double precision AS x_m,
           c.postmile_at_start + p.x_m::double precision / 1609.344 AS postmile,
           p.speed_mps::double precision AS speed_mps,
           sp.target_speed_mps::double precision AS target_speed_mps,
           (p.speed_mps - sp.target_speed_mps)::double precision AS speed_error_mps,
           sp.is_buffer,
           p.is_controller_engaged,
           extract(epoch FROM p.ts - r.published_at)::double precision AS plan_age_s
    FROM fact_vehicle_ping p
    JOIN dim_vehicle v ON v.vehicle_id = p.vehicle_id
    JOIN dim_corridor c ON c.corridor_id = v.corridor_id
    JOIN grid g ON g.corridor_id = v.corridor_id
    CROSS JOIN LATERAL (
        SELECT seg.i24_segment_id
        FROM dim_i24_segment seg
        WHERE seg.i24_segment_id = g.segment_ids[width_bucket(p.x_m::double precision, g.starts)]
          AND p.x_m < seg.end_x_m
        LIMIT 1
    ) s
    CROSS JOIN LATERAL (
        SELECT run.published_at
        FROM plan_run run
        WHERE run.corridor_id = v.corridor_id AND run.plan_id = p.plan_id
        LIMIT 1
    ) r
    CROSS JOIN LATERAL (
        SELECT plan.lane, plan.target_speed_mps, plan.is_buffer
        FROM fact_speed_planner plan
        WHERE plan.corridor_id = v.corridor_id
          AND plan.plan_id = p.plan_id
          AND plan.lane = coalesce(p.lane, v.assigned_lane)
          AND plan.i24_segment_id = s.i24_segment_id
        LIMIT 1
    ) sp
    WHERE p.plan_id IS NOT NULL AND p.x_m IS NOT NULL;
"""


def upgrade() -> None:
    op.execute(EQUALITY_JOINS)
    op.execute(COMMENT)


def downgrade() -> None:
    op.execute(KEY_LOOKUPS)
    op.execute(COMMENT)
