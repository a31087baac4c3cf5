"""A ping's time in an Edie box ends at the car's next ping, on the corridor or off it.

Revision ID: 0017
Revises: 0016
Create Date: 2026-12-05 06:50:00+00:00

`analytics.edie_field` (0002, 0012) dropped the pings without a corridor position (`x_m` NULL:
off the corridor) before it looked for each ping's successor, so a ping's "next ping" was the
car's next one *on the corridor*. A car that left the corridor for three seconds and came back
credited its last ping before leaving with the whole excursion (4 s and 40 m at 10 m/s, not 1 s
and 10 m), against docs/analytics.md's rule that a ping stands for the time until the same
car's next ping: density, flow and fuel ran high in the boxes where cars leave and rejoin
(analytics audit, 2026-12-05). The successor is now found among all the car's pings of the
window; the pings off the corridor are left out after that, as before, so they still fill no
box. Same signature and columns: CREATE OR REPLACE keeps analytics.edie_boxes and its comment.
"""

import importlib.util
from collections.abc import Sequence
from pathlib import Path

from alembic import op

revision: str = "0017"
down_revision: str | None = "0016"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# 0012's function with `x_m IS NOT NULL` moved from `ordered` (before the window) to
# `samples` (after it).
SUCCESSOR_OF_EVERY_PING = """
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
        WHERE p.ts >= since AND p.ts < until
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
        WHERE x_m IS NOT NULL
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


def _revision_0012_edie_field() -> str:
    """0012's definition, to put back on downgrade (migrations are frozen; it is read, not
    imported by name, since a revision's module name starts with a digit)."""
    path = Path(__file__).with_name("0012_vehicle_assignment_history.py")
    spec = importlib.util.spec_from_file_location("vehicle_assignment_history_0012", path)
    if spec is None or spec.loader is None:
        raise RuntimeError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return str(module.EDIE_FIELD)


def upgrade() -> None:
    op.execute(SUCCESSOR_OF_EVERY_PING)


def downgrade() -> None:
    op.execute(_revision_0012_edie_field())
