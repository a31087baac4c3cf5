"""The hourly ping rate counts the seconds a car was heard, not its breaks.

Revision ID: 0015
Revises: 0014
Create Date: 2026-12-04 23:40:00+00:00

`ping_rate_hourly.ping_rate_hz` was (n - 1) / (last - first) over the hour's pings, so a car
that pinged at exactly 1 Hz for ten minutes, stopped for half an hour (the field team's drivers
took breaks) and drove ten minutes more read 0.33 Hz, and the docs' "cars that ping slowly"
query flagged a healthy agent (analytics audit). The rate is now the pings per second over the
intervals between consecutive pings of at most 60 s: a longer silence is a car switched off or
an agent not running, not a slow one. A car pinging every 10 s still reads 0.1 Hz; an hour
whose pings are all more than 60 s apart has no rate (NULL), as an hour of one ping had.
"""

from collections.abc import Sequence

from alembic import op

revision: str = "0015"
down_revision: str | None = "0014"
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None

# Same columns as 0003's function, so the view over it stands as it is.
_SIGNATURE = """
CREATE OR REPLACE FUNCTION analytics.ping_rate_hourly_between(since timestamptz, until timestamptz)
RETURNS TABLE (
    vehicle_id text,
    hour timestamptz,
    pings bigint,
    first_ts timestamptz,
    last_ts timestamptz,
    ping_rate_hz double precision,
    latency_mean_s double precision,
    latency_p50_s double precision,
    latency_p95_s double precision,
    latency_max_s double precision
)
LANGUAGE sql STABLE AS $$
"""

_LATENCIES = """
           avg(extract(epoch FROM p.received_at - p.ts))::double precision,
           percentile_cont(0.5) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts)),
           percentile_cont(0.95) WITHIN GROUP (ORDER BY extract(epoch FROM p.received_at - p.ts)),
           max(extract(epoch FROM p.received_at - p.ts))::double precision
"""

WHILE_HEARD = (
    _SIGNATURE
    + """
    SELECT p.vehicle_id,
           p.hour,
           count(*),
           min(p.ts),
           max(p.ts),
           (count(*) FILTER (WHERE p.gap_s <= 60))::double precision
               / NULLIF(sum(p.gap_s) FILTER (WHERE p.gap_s <= 60), 0),
"""
    + _LATENCIES
    + """
    FROM (
        SELECT ping.vehicle_id,
               ping.ts,
               ping.received_at,
               date_trunc('hour', ping.ts, 'UTC') AS hour,
               extract(epoch FROM ping.ts - lag(ping.ts) OVER (
                   PARTITION BY ping.vehicle_id, date_trunc('hour', ping.ts, 'UTC')
                   ORDER BY ping.ts
               ))::double precision AS gap_s
        FROM fact_vehicle_ping ping
        WHERE ping.ts >= since AND ping.ts < until
    ) p
    GROUP BY p.vehicle_id, p.hour
$$;
"""
)

FIRST_TO_LAST = (
    _SIGNATURE
    + """
    SELECT p.vehicle_id,
           date_trunc('hour', p.ts, 'UTC'),
           count(*),
           min(p.ts),
           max(p.ts),
           CASE WHEN count(*) > 1
                THEN (count(*) - 1) / extract(epoch FROM max(p.ts) - min(p.ts))::double precision
           END,
"""
    + _LATENCIES
    + """
    FROM fact_vehicle_ping p
    WHERE p.ts >= since AND p.ts < until
    GROUP BY p.vehicle_id, date_trunc('hour', p.ts, 'UTC')
$$;
"""
)

COMMENT = """
COMMENT ON VIEW analytics.ping_rate_hourly IS
    'One row per vehicle per UTC hour: pings, ping rate (Hz, over the intervals between pings '
    'of at most 60 s) and latency received_at - ts (s).';
"""

OLD_COMMENT = """
COMMENT ON VIEW analytics.ping_rate_hourly IS
    'One row per vehicle per UTC hour: pings, ping rate (Hz) and latency received_at - ts (s).';
"""


def upgrade() -> None:
    op.execute(WHILE_HEARD)
    op.execute(COMMENT)


def downgrade() -> None:
    op.execute(FIRST_TO_LAST)
    op.execute(OLD_COMMENT)
