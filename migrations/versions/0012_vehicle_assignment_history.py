"""A vehicle's assignments over time, so a ping counts in the lane and corridor it was driving.

Revision ID: 0012
Revises: 0011
Create Date: 2026-12-03 14:40:00+00:00

`analytics.plan_adherence` compared a ping without a reported lane with the target of its
vehicle's lane *now* (`coalesce(p.lane, v.assigned_lane)` on `dim_vehicle`), and it and
`analytics.edie_field` put each ping on its vehicle's corridor *now*. After an operator moved a
car from lane 2 to lane 3 (PUT /api/v1/vehicles/{id}/assignment), yesterday's pings counted in
lane 3: the change rewrote the car's whole history.

`dim_vehicle_assignment` keeps the history, a type 2 slowly changing dimension: one row per
vehicle per assignment (corridor, route, lane) with the half-open span [valid_from, valid_to)
it was in force; the row in force now has valid_to = 'infinity'. The views join each ping to
the row whose span holds its ts, and keep their columns and meaning otherwise.

A trigger on dim_vehicle keeps the history, in the transaction that changes the vehicle: every
writer (the assignment API, the dashboard's form, `smoothfleet vehicles add|import`, the seed,
an operator's SQL) is covered, and none has to remember to. A new vehicle opens its first row;
a change of corridor, route or lane closes the open row and opens the next at the clock time of
the change; an update that leaves all three as they were (a controller change, a no-op
reassignment, a re-import of the same roster) adds nothing.

The first row of each vehicle, the backfilled ones included, starts at '-infinity', not at the
vehicle's created_at: a ping's ts is the car's GPS clock, which may be earlier than the
server's row (pings spooled on the car, imported recordings, a skewed clock), and the first
assignment is the only one that can have applied to such a ping; an inner join on a span from
created_at would silently drop it from the views. For the vehicles existing at this upgrade
their current assignment is the only one known (when it began is not recorded anywhere), so
the backfill leaves every view's answer as it was before the upgrade; only changes from now on
split a car's history.
"""

import importlib.util
from collections.abc import Sequence
from pathlib import Path

import sqlalchemy as sa
from alembic import op

revision: str = "0012"
down_revision: str | None = "0011"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

TABLE = "dim_vehicle_assignment"

HISTORY_TRIGGER = """
-- A new vehicle's first assignment covers all time before it (see the migration's docstring);
-- a change closes the open row and opens the next at the clock time of the change:
-- clock_timestamp(), not now(), so two changes in one transaction get their own times, and a
-- transaction that started before another's change but waited for its row lock still comes
-- after it. An open row from this very instant or later (a clock stepped back) is rewritten in
-- place rather than closed with an empty span.
CREATE FUNCTION record_vehicle_assignment() RETURNS trigger
LANGUAGE plpgsql AS $$
DECLARE
    changed_at timestamptz := clock_timestamp();
BEGIN
    IF TG_OP = 'INSERT' THEN
        INSERT INTO dim_vehicle_assignment
            (vehicle_id, valid_from, valid_to, corridor_id, route, assigned_lane)
        VALUES (NEW.vehicle_id, '-infinity', 'infinity', NEW.corridor_id, NEW.route,
                NEW.assigned_lane);
        RETURN NULL;
    END IF;
    UPDATE dim_vehicle_assignment
       SET corridor_id = NEW.corridor_id, route = NEW.route, assigned_lane = NEW.assigned_lane
     WHERE vehicle_id = NEW.vehicle_id AND valid_to = 'infinity' AND valid_from >= changed_at;
    IF FOUND THEN
        RETURN NULL;
    END IF;
    UPDATE dim_vehicle_assignment
       SET valid_to = changed_at
     WHERE vehicle_id = NEW.vehicle_id AND valid_to = 'infinity';
    INSERT INTO dim_vehicle_assignment
        (vehicle_id, valid_from, valid_to, corridor_id, route, assigned_lane)
    VALUES (NEW.vehicle_id, changed_at, 'infinity', NEW.corridor_id, NEW.route,
            NEW.assigned_lane);
    RETURN NULL;
END
$$;
COMMENT ON FUNCTION record_vehicle_assignment() IS
    'Keeps dim_vehicle_assignment in step with dim_vehicle (trigger function).';

CREATE TRIGGER vehicle_assignment_opened
    AFTER INSERT ON dim_vehicle
    FOR EACH ROW EXECUTE FUNCTION record_vehicle_assignment();

CREATE TRIGGER vehicle_assignment_changed
    AFTER UPDATE OF corridor_id, route, assigned_lane ON dim_vehicle
    FOR EACH ROW
    WHEN ((OLD.corridor_id, OLD.route, OLD.assigned_lane)
          IS DISTINCT FROM (NEW.corridor_id, NEW.route, NEW.assigned_lane))
    EXECUTE FUNCTION record_vehicle_assignment();
"""

BACKFILL = """
INSERT INTO dim_vehicle_assignment
    (vehicle_id, valid_from, valid_to, corridor_id, route, assigned_lane)
SELECT vehicle_id, '-infinity', 'infinity', corridor_id, route, assigned_lane
FROM dim_vehicle;
"""

DROP_HISTORY_TRIGGER = """
DROP TRIGGER vehicle_assignment_changed ON dim_vehicle;
DROP TRIGGER vehicle_assignment_opened ON dim_vehicle;
DROP FUNCTION record_vehicle_assignment();
"""

# 0004's plan_adherence with the ping's corridor and fallback lane from the assignment in
# force at its ts instead of the vehicle's current one.
PLAN_ADHERENCE = """
-- A ping that names the plan it follows is compared with that plan's target for the lane it
-- drove in (its reported lane, else the lane its vehicle was assigned at the ping's ts) and the
-- sub-segment holding its x_m on the corridor it was assigned then, found by binary search over
-- the corridor's segment starts (width_bucket).
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
               a.corridor_id,
               coalesce(p.lane, a.assigned_lane) AS lane,
               g.segment_ids[width_bucket(p.x_m::double precision, g.starts)] AS i24_segment_id
        FROM fact_vehicle_ping p
        JOIN dim_vehicle_assignment a
          ON a.vehicle_id = p.vehicle_id AND p.ts >= a.valid_from AND p.ts < a.valid_to
        JOIN grid g ON g.corridor_id = a.corridor_id
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
COMMENT ON VIEW analytics.plan_adherence IS
    'One row per ping that follows a plan: its speed against the plan''s target where it was.';
"""

# 0002's edie_field with each ping on the corridor its vehicle was assigned at the ping's ts.
# Same signature and columns, so CREATE OR REPLACE keeps analytics.edie_boxes and the comment.
EDIE_FIELD = """
CREATE OR REPLACE FUNCTION analytics.edie_field(
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
               a.corridor_id,
               p.ts,
               p.x_m::double precision AS x_m,
               p.speed_mps::double precision AS speed_mps,
               p.accel_mps2::double precision AS accel_mps2,
               extract(epoch FROM lead(p.ts) OVER by_vehicle - p.ts)::double precision
                   AS gap_s,
               lead(p.speed_mps) OVER by_vehicle::double precision AS next_speed_mps
        FROM fact_vehicle_ping p
        JOIN dim_vehicle_assignment a
          ON a.vehicle_id = p.vehicle_id AND p.ts >= a.valid_from AND p.ts < a.valid_to
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
"""


def _previous_sql(filename: str, names: Sequence[str]) -> dict[str, str]:
    """Definitions of an earlier revision, to put back on downgrade (as 0003 does)."""
    path = Path(__file__).with_name(filename)
    spec = importlib.util.spec_from_file_location(f"previous_{path.stem}", path)
    if spec is None or spec.loader is None:
        raise RuntimeError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return {name: getattr(module, name) for name in names}


def upgrade() -> None:
    op.create_table(
        TABLE,
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("valid_from", sa.DateTime(timezone=True), nullable=False),
        sa.Column(
            "valid_to",
            sa.DateTime(timezone=True),
            server_default=sa.text("'infinity'"),
            nullable=False,
        ),
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("route", sa.Text(), nullable=False),
        sa.Column("assigned_lane", sa.SmallInteger(), nullable=False),
        sa.CheckConstraint(
            "valid_from < valid_to", name=op.f("ck_dim_vehicle_assignment_span_positive")
        ),
        sa.CheckConstraint(
            "assigned_lane >= 1", name=op.f("ck_dim_vehicle_assignment_lane_positive")
        ),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_dim_vehicle_assignment_vehicle_id_dim_vehicle"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_dim_vehicle_assignment_corridor_id_dim_corridor"),
        ),
        sa.PrimaryKeyConstraint("vehicle_id", "valid_from", name=op.f("pk_dim_vehicle_assignment")),
        comment=(
            "One row per vehicle per assignment (corridor, route, lane), in force over "
            "[valid_from, valid_to); the current one has valid_to = infinity."
        ),
    )
    op.create_index(
        "ix_dim_vehicle_assignment_vehicle_id",
        TABLE,
        ["vehicle_id"],
        unique=True,
        postgresql_where=sa.text("valid_to = 'infinity'::timestamptz"),
    )
    op.execute(BACKFILL)
    op.execute(HISTORY_TRIGGER)
    op.execute(PLAN_ADHERENCE)
    op.execute(EDIE_FIELD)


def downgrade() -> None:
    plan_adherence = _previous_sql("0004_plan_adherence_hash_joins.py", ["EQUALITY_JOINS"])
    edie_field = _previous_sql("0002_analytics_views.py", ["EDIE_FIELD"])
    op.execute(plan_adherence["EQUALITY_JOINS"])
    # 0002 creates the function and the view on it; the view goes first and comes back with it.
    op.execute(
        "DROP VIEW analytics.edie_boxes;"
        " DROP FUNCTION analytics.edie_field(timestamptz, timestamptz, double precision,"
        " double precision);"
    )
    op.execute(edie_field["EDIE_FIELD"])
    op.execute(DROP_HISTORY_TRIGGER)
    op.drop_index("ix_dim_vehicle_assignment_vehicle_id", table_name=TABLE)
    op.drop_table(TABLE)
