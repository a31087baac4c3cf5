"""The SQL of the ping fast path, in one place.

A small group (the common case: a few single pings that arrived together) is one statement on
an autocommit connection, `INSERT ... VALUES ... ON CONFLICT DO NOTHING RETURNING`: one round
trip that also commits, so the request is answered after one visit to PostgreSQL instead of
four (COPY start, COPY end, INSERT, COMMIT). The rows it returns are those inserted; a sent row
not among them was already stored.

A larger group (batch uploads) is first copied straight into fact_vehicle_ping (binary COPY in
one transaction: raw COPY's speed). A car's upload holds new rows but when it resends after a
lost acknowledgement; then the COPY fails on the unique key, nothing of it is kept, and the
group is written in one transaction through a temporary table, which tells which were new:
1. binary COPY of the rows (numbered n = 0, 1, ...) into the connection's temporary table
   `ping_incoming` (emptied at every commit); psycopg formats the rows in C;
2. one INSERT ... SELECT from it into fact_vehicle_ping with ON CONFLICT DO NOTHING, so a resent
   ping is a no-op; the same statement returns the numbers of the rows that were NOT inserted
   (already stored), usually none, which is how each request learns its own counts;
3. COMMIT, and only then the requests are answered.
"""

from __future__ import annotations

import functools

# (column, PostgreSQL type) in the order of app.ingest.pings.PingRow, with x_m (computed by the
# writer from lat/lon) after lane.
PING_COLUMNS: tuple[tuple[str, str], ...] = (
    ("vehicle_id", "text"),
    ("ts", "timestamptz"),
    ("received_at", "timestamptz"),
    ("lat", "float8"),
    ("lon", "float8"),
    ("speed_mps", "float4"),
    ("accel_mps2", "float4"),
    ("heading_deg", "float4"),
    ("lane", "int2"),
    ("x_m", "float4"),
    ("is_acc_engaged", "bool"),
    ("is_controller_engaged", "bool"),
    ("controller", "text"),
    ("acc_speed_setting_mph", "float4"),
    ("acc_gap_setting", "int2"),
    ("is_lead_present", "bool"),
    ("lead_distance_m", "float4"),
    ("lead_rel_speed_mps", "float4"),
    ("plan_id", "int8"),
    ("policy_sha256", "text"),
)
_NAMES = ", ".join(name for name, _ in PING_COLUMNS)

# COPY needs the types of a binary stream: the row number, then the columns.
COPY_TYPES = ["int4", *(pg_type for _, pg_type in PING_COLUMNS)]

CREATE_INCOMING = (
    "CREATE TEMPORARY TABLE IF NOT EXISTS ping_incoming (n int4, LIKE fact_vehicle_ping) "
    "ON COMMIT DELETE ROWS"
)

# Up to this many rows a group takes the one-statement path; beyond it COPY's cheaper
# formatting of each row pays for its extra round trips (bench/ingest.py).
SMALL_GROUP_ROWS = 64


@functools.cache
def insert_values(rows: int) -> str:
    """The one-statement INSERT of `rows` rows, with PostgreSQL's own $n placeholders (a raw
    cursor sends it as it is: psycopg parses, and caches, only short %s queries), one text per
    size, so each is prepared once."""
    width = len(PING_COLUMNS)
    tuples = (
        "(" + ",".join(f"${row * width + column + 1}" for column in range(width)) + ")"
        for row in range(rows)
    )
    return (
        f"INSERT INTO fact_vehicle_ping ({_NAMES}) VALUES {','.join(tuples)} "
        "ON CONFLICT (vehicle_id, ts) DO NOTHING RETURNING vehicle_id, ts"
    )


COPY_STORED = f"COPY fact_vehicle_ping ({_NAMES}) FROM STDIN (FORMAT BINARY)"

COPY_INCOMING = f"COPY ping_incoming (n, {_NAMES}) FROM STDIN (FORMAT BINARY)"

INSERT_FROM_INCOMING = f"""
WITH inserted AS (
    INSERT INTO fact_vehicle_ping ({_NAMES})
    SELECT {_NAMES} FROM ping_incoming
    ON CONFLICT (vehicle_id, ts) DO NOTHING
    RETURNING vehicle_id, ts
)
SELECT incoming.n
FROM ping_incoming AS incoming
LEFT JOIN inserted USING (vehicle_id, ts)
WHERE inserted.vehicle_id IS NULL
"""

# What a car said in a ping, beside its key: a resend differing in any of these is no resend of
# the stored ping but another ping at the same (vehicle_id, ts). received_at is the server's and
# x_m derived from lat/lon, so neither tells the two apart.
CONTENT_COLUMNS: tuple[tuple[str, str], ...] = tuple(
    (name, pg_type)
    for name, pg_type in PING_COLUMNS
    if name not in ("vehicle_id", "ts", "received_at", "x_m")
)

# The numbers n of the sent rows whose stored row at the same key says something else, the sent
# values cast to the columns' types as storing them would (a float4 column's rounding):
# parameters are one array per column, n first, then vehicle_id, ts and CONTENT_COLUMNS.
CONFLICTING = f"""
SELECT sent.n
FROM unnest($1::int4[], $2::text[], $3::timestamptz[], {
    ", ".join(f"${number}::{pg_type}[]" for number, (_, pg_type) in enumerate(CONTENT_COLUMNS, 4))
}) AS sent (n, vehicle_id, ts, {", ".join(name for name, _ in CONTENT_COLUMNS)})
JOIN fact_vehicle_ping AS stored USING (vehicle_id, ts)
WHERE ({", ".join(f"stored.{name}" for name, _ in CONTENT_COLUMNS)})
    IS DISTINCT FROM ({", ".join(f"sent.{name}" for name, _ in CONTENT_COLUMNS)})
"""
