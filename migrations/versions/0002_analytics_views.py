"""Analytics views: engagement, ping rate and latency, INRIX latency, plan adherence, Edie fields.

Revision ID: 0002
Revises: 0001
Create Date: 2026-11-23 09:40:00+00:00

Everything lives in the schema `analytics`, so analysts find the common questions in one place
(`\\dv analytics.*` in psql) and `smoothfleet analytics export` can list them. Days and hours are
UTC. docs/analytics.md explains each column and gives example queries.

The energy model is the paper's simplified polynomial (sidebar "Vehicle Energy Models") with the
published RAV4 coefficients of ../shared/reference/energy-model.md; the Edie fields follow the
paper's "Results" section (boxes of h_t x h_x = 10 s x 200 m).
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0002"
down_revision: str | None = "0001"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


FUEL_MODEL = """
-- Paper, sidebar "Vehicle Energy Models": f(v, a, theta) = max(beta, C(v) + P(v) a + Q(v) a_+^2
-- + Z(v) theta) in grams of fuel per second, with the RAV4 fit of the CIRCLES simulator
-- (energy-model.md): a_+ = max(a, 0); the floor beta holds only while v <= vc = 5.98 m/s.
CREATE FUNCTION analytics.fuel_rate_g_per_s(
    speed_mps double precision,
    accel_mps2 double precision,
    grade_rad double precision DEFAULT 0
) RETURNS double precision
LANGUAGE sql IMMUTABLE PARALLEL SAFE AS $$
    SELECT greatest(
        CASE WHEN speed_mps <= 5.98 THEN 0.013111753095302022 ELSE 0 END,
        -- C(v) = C0 + C1 v + C2 v^2 + C3 v^3 (C2 = 0 in this fit)
        0.14631964767035743
            + 0.012179045946260292 * speed_mps
            + 2.7432588728174234e-05 * speed_mps * speed_mps * speed_mps
        -- P(v) a = (p0 + p1 v + p2 v^2) a
        + (0.04553801347643801
            + 0.047436831067050676 * speed_mps
            + 0.0018022443124799303 * speed_mps * speed_mps) * accel_mps2
        -- Q(v) a_+^2 = (q0 + q1 v) max(a, 0)^2 (q0 = 0 in this fit)
        + 0.02609037187916979 * speed_mps * greatest(accel_mps2, 0) * greatest(accel_mps2, 0)
        -- Z(v) theta = (z0 + z1 v) theta
        + (1.4940081773441736 + 1.2718495543500672 * speed_mps) * grade_rad
    )
$$;
COMMENT ON FUNCTION analytics.fuel_rate_g_per_s(double precision, double precision,
    double precision) IS
    'Fuel rate (g/s) of the paper''s simplified energy model, RAV4 coefficients.';
"""

EDIE_FIELD = """
-- Paper, "Results": Edie's generalised definitions on boxes of h_t x h_x. Each ping stands for
-- the time until the same vehicle's next ping (one GPS second when the next ping is missing or
-- more than 5 s away: the car left the corridor or lost its fix, and we do not interpolate across
-- that), spent at its speed in the box that holds its (ts, x_m). Grade is taken as 0 (the
-- corridor has no elevation profile yet); acceleration is the ping's own or the finite difference
-- to the next ping.
CREATE FUNCTION analytics.edie_field(
    since timestamptz,
    until timestamptz,
    h_t_s double precision DEFAULT 10,
    h_x_m double precision DEFAULT 200
) RETURNS TABLE (
    corridor_id text,
    t_start timestamptz,
    x_start_m double precision,
    postmile_start double precision,
    vehicles bigint,
    pings bigint,
    time_s double precision,
    distance_m double precision,
    fuel_g double precision,
    density_veh_per_m double precision,
    flow_veh_per_s double precision,
    fuel_rate_density_g_per_s_m double precision,
    speed_mps double precision,
    fuel_rate_per_vehicle_g_per_s double precision,
    fuel_per_distance_g_per_m double precision
)
LANGUAGE sql STABLE AS $$
    WITH ordered AS (
        SELECT p.vehicle_id,
               v.corridor_id,
               p.ts,
               p.x_m::double precision AS x_m,
               p.speed_mps::double precision AS speed_mps,
               p.accel_mps2::double precision AS accel_mps2,
               extract(epoch FROM lead(p.ts) OVER by_vehicle - p.ts)::double precision
                   AS gap_s,
               lead(p.speed_mps) OVER by_vehicle::double precision AS next_speed_mps
        FROM fact_vehicle_ping p
        JOIN dim_vehicle v ON v.vehicle_id = p.vehicle_id
        WHERE p.ts >= since AND p.ts < until AND p.x_m IS NOT NULL
        WINDOW by_vehicle AS (PARTITION BY p.vehicle_id ORDER BY p.ts)
    ),
    samples AS (
        SELECT vehicle_id, corridor_id, ts, x_m, speed_mps,
               CASE WHEN gap_s <= 5 THEN gap_s ELSE 1.0 END AS dt_s,
               coalesce(
                   accel_mps2,
                   CASE WHEN gap_s <= 5 THEN (next_speed_mps - speed_mps) / gap_s END,
                   0.0
               ) AS accel_mps2
        FROM ordered
    ),
    boxes AS (
        SELECT s.corridor_id,
               floor(extract(epoch FROM s.ts) / h_t_s) AS t_index,
               floor(s.x_m / h_x_m) AS x_index,
               count(DISTINCT s.vehicle_id) AS vehicles,
               count(*) AS pings,
               sum(s.dt_s) AS time_s,
               sum(s.speed_mps * s.dt_s) AS distance_m,
               sum(analytics.fuel_rate_g_per_s(s.speed_mps, s.accel_mps2) * s.dt_s) AS fuel_g
        FROM samples s
        GROUP BY s.corridor_id, t_index, x_index
    )
    SELECT b.corridor_id,
           to_timestamp(b.t_index * h_t_s),
           b.x_index * h_x_m,
           c.postmile_at_start + b.x_index * h_x_m / 1609.344,
           b.vehicles,
           b.pings,
           b.time_s,
           b.distance_m,
           b.fuel_g,
           b.time_s / (h_t_s * h_x_m),
           b.distance_m / (h_t_s * h_x_m),
           b.fuel_g / (h_t_s * h_x_m),
           b.distance_m / b.time_s,
           b.fuel_g / b.time_s,
           b.fuel_g / nullif(b.distance_m, 0)
    FROM boxes b
    JOIN dim_corridor c ON c.corridor_id = b.corridor_id
$$;
COMMENT ON FUNCTION analytics.edie_field(timestamptz, timestamptz, double precision,
    double precision) IS
    'Edie''s generalised density, flow and fuel rate density of the fleet''s pings in '
    'h_t x h_x boxes between since and until.';

CREATE VIEW analytics.edie_boxes AS
    SELECT * FROM analytics.edie_field('-infinity', 'infinity');
COMMENT ON VIEW analytics.edie_boxes IS
    'One row per corridor, 10 s x 200 m box with pings: Edie density, flow, fuel (paper, Results).';
"""

ENGAGEMENT = """
-- Paper, "Results": "the controllers were engaged 38% of all times". A ping is one GPS second
-- of a vehicle on its corridor (x_m map-matched), so shares are shares of time on the corridor.
CREATE VIEW analytics.engagement_daily AS
    SELECT p.vehicle_id,
           (p.ts AT TIME ZONE 'UTC')::date AS day,
           count(*) AS pings,
           count(*) FILTER (WHERE p.is_controller_engaged) AS engaged_pings,
           count(*) FILTER (WHERE p.is_acc_engaged) AS acc_engaged_pings,
           (count(*) FILTER (WHERE p.is_controller_engaged))::double precision / count(*)
               AS engagement_share,
           (count(*) FILTER (WHERE p.is_acc_engaged))::double precision / count(*)
               AS acc_engaged_share
    FROM fact_vehicle_ping p
    WHERE p.x_m IS NOT NULL
    GROUP BY p.vehicle_id, day;
COMMENT ON VIEW analytics.engagement_daily IS
    'One row per vehicle per UTC day on its corridor: share of pings with the controller engaged.';

CREATE VIEW analytics.engagement_fleet_daily AS
    SELECT day,
           count(*) AS vehicles,
           sum(pings)::bigint AS pings,
           sum(engaged_pings)::bigint AS engaged_pings,
           sum(engaged_pings)::double precision / sum(pings) AS engagement_share
    FROM analytics.engagement_daily
    GROUP BY day;
COMMENT ON VIEW analytics.engagement_fleet_daily IS
    'One row per UTC day: the fleet''s pooled engagement share (paper: 38 % on 11/16, 78 % on '
    '11/17).';
"""

PING_RATE = """
-- Ping rate over the span a vehicle was heard in the hour ((n - 1) pings between its first and
-- last ping), and latency = received_at - ts (server clock minus the car's GPS clock; spooled
-- store-and-forward uploads show up here as long latencies).
CREATE VIEW analytics.ping_rate_hourly AS
    SELECT p.vehicle_id,
           date_trunc('hour', p.ts, 'UTC') AS hour,
           count(*) AS pings,
           min(p.ts) AS first_ts,
           max(p.ts) AS last_ts,
           CASE WHEN count(*) > 1
                THEN (count(*) - 1) / extract(epoch FROM max(p.ts) - min(p.ts))::double precision
           END AS ping_rate_hz,
           avg(extract(epoch FROM p.received_at - p.ts))::double precision AS latency_mean_s,
           percentile_cont(0.5) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts))
               AS latency_p50_s,
           percentile_cont(0.95) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts))
               AS latency_p95_s,
           max(extract(epoch FROM p.received_at - p.ts))::double precision AS latency_max_s
    FROM fact_vehicle_ping p
    GROUP BY p.vehicle_id, hour;
COMMENT ON VIEW analytics.ping_rate_hourly IS
    'One row per vehicle per UTC hour: pings, ping rate (Hz) and latency received_at - ts (s).';

CREATE VIEW analytics.fleet_ping_hourly AS
    SELECT date_trunc('hour', p.ts, 'UTC') AS hour,
           count(*) AS pings,
           count(DISTINCT p.vehicle_id) AS vehicles,
           count(*) / 3600.0::double precision AS pings_per_s,
           percentile_cont(0.5) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts))
               AS latency_p50_s,
           percentile_cont(0.95) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts))
               AS latency_p95_s
    FROM fact_vehicle_ping p
    GROUP BY hour;
COMMENT ON VIEW analytics.fleet_ping_hourly IS
    'One row per UTC hour: pings, vehicles heard, mean pings per second, latency percentiles (s).';
"""

INRIX_LATENCY = """
-- INRIX speeds arrive minutes after the time they describe (paper: the planner predicts past
-- this latency). One provider snapshot = all segments with the same measured_at.
CREATE VIEW analytics.inrix_latency AS
    SELECT e.corridor_id,
           e.measured_at,
           count(*) AS segments,
           count(*) FILTER (WHERE e.score = 30) AS realtime_segments,
           count(*) FILTER (WHERE e.is_closed) AS closed_segments,
           min(e.received_at) AS received_at,
           extract(epoch FROM min(e.received_at) - e.measured_at)::double precision AS latency_s,
           avg(e.speed_mps)::double precision AS mean_speed_mps
    FROM fact_inrix_estimate e
    GROUP BY e.corridor_id, e.measured_at;
COMMENT ON VIEW analytics.inrix_latency IS
    'One row per corridor per INRIX snapshot (measured_at): segments and latency (s) until '
    'received.';
"""

PLAN_ADHERENCE = """
-- A ping that names the plan it follows is compared with that plan's target for the lane it
-- drove in (its reported lane, else its assigned lane) and the sub-segment holding its x_m.
CREATE VIEW analytics.plan_adherence AS
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
    JOIN plan_run r ON r.corridor_id = v.corridor_id AND r.plan_id = p.plan_id
    JOIN dim_i24_segment s
      ON s.corridor_id = v.corridor_id AND p.x_m >= s.start_x_m AND p.x_m < s.end_x_m
    JOIN fact_speed_planner sp
      ON sp.corridor_id = r.corridor_id
     AND sp.plan_id = r.plan_id
     AND sp.i24_segment_id = s.i24_segment_id
     AND sp.lane = coalesce(p.lane, v.assigned_lane)
    WHERE p.plan_id IS NOT NULL AND p.x_m IS NOT NULL;
COMMENT ON VIEW analytics.plan_adherence IS
    'One row per ping that follows a plan: its speed against the plan''s target where it was.';

CREATE VIEW analytics.plan_adherence_daily AS
    SELECT vehicle_id,
           (ts AT TIME ZONE 'UTC')::date AS day,
           count(*) AS pings,
           count(*) FILTER (WHERE is_controller_engaged) AS engaged_pings,
           avg(speed_error_mps) AS mean_speed_error_mps,
           avg(abs(speed_error_mps)) AS mean_abs_speed_error_mps,
           sqrt(avg(speed_error_mps * speed_error_mps)) AS rms_speed_error_mps,
           avg(abs(speed_error_mps)) FILTER (WHERE is_controller_engaged)
               AS engaged_mean_abs_speed_error_mps
    FROM analytics.plan_adherence
    GROUP BY vehicle_id, day;
COMMENT ON VIEW analytics.plan_adherence_daily IS
    'One row per vehicle per UTC day: speed minus planned target (m/s), mean, mean |.|, RMS.';
"""


def upgrade() -> None:
    op.execute("CREATE SCHEMA analytics")
    op.execute("COMMENT ON SCHEMA analytics IS 'Views and functions for analysts (read-only).'")
    op.execute(FUEL_MODEL)
    op.execute(EDIE_FIELD)
    op.execute(ENGAGEMENT)
    op.execute(PING_RATE)
    op.execute(INRIX_LATENCY)
    op.execute(PLAN_ADHERENCE)


def downgrade() -> None:
    op.execute("DROP SCHEMA analytics CASCADE")
