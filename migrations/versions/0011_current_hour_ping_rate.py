"""fleet_ping_hourly: the hour still running is divided by the time it has run, not 3,600 s.

Revision ID: 0011
Revises: 0010
Create Date: 2026-12-03 09:40:00+00:00

`pings_per_s` divided every hour's pings by 3,600 s, so for the hour in progress it read as if
the fleet had been silent for the rest of it: at half past, a fleet pinging at 100/s read
50/s. The hour still running is now divided by the seconds it has run (at least a minute: a
ping a car stamped a little ahead may fall in an hour not yet begun). Hours that are over keep
their figure.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0011"
down_revision: str | None = "0010"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# One definition, two divisors: the signature and the other columns are 0003's.
FUNCTION = """
CREATE OR REPLACE FUNCTION analytics.fleet_ping_hourly_between(since timestamptz, until timestamptz)
RETURNS TABLE (
    hour timestamptz,
    pings bigint,
    vehicles bigint,
    pings_per_s double precision,
    latency_p50_s double precision,
    latency_p95_s double precision
)
LANGUAGE sql STABLE AS $$
    SELECT date_trunc('hour', p.ts, 'UTC'),
           count(*),
           count(DISTINCT p.vehicle_id),
           count(*) / ({seconds})::double precision,
           percentile_cont(0.5) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts)),
           percentile_cont(0.95) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts))
    FROM fact_vehicle_ping p
    WHERE p.ts >= since AND p.ts < until
    GROUP BY date_trunc('hour', p.ts, 'UTC')
$$;
"""

WHOLE_HOUR = FUNCTION.format(seconds="3600.0")
ELAPSED = FUNCTION.format(
    seconds="least(3600.0, greatest(60.0,"
    " extract(epoch FROM now() - date_trunc('hour', p.ts, 'UTC'))))"
)


def upgrade() -> None:
    op.execute(ELAPSED)


def downgrade() -> None:
    op.execute(WHOLE_HOUR)
