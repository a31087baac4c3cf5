"""The SQL of the ping fast path, in one place.

A group of requests' pings is written with one statement: the columns travel as arrays and
`unnest` turns them back into rows, so one round trip carries thousands of pings with their
types checked by PostgreSQL. `ON CONFLICT DO NOTHING` makes a resent ping a no-op, and
`RETURNING` names the keys actually inserted, which is how each request learns its own
accepted and duplicate counts.
"""

from __future__ import annotations

# (column, array type) in the order of app.ingest.pings.PingRow, with x_m (computed by the
# writer from lat/lon) after lane.
PING_COLUMNS: tuple[tuple[str, str], ...] = (
    ("vehicle_id", "text[]"),
    ("ts", "timestamptz[]"),
    ("received_at", "timestamptz[]"),
    ("lat", "float8[]"),
    ("lon", "float8[]"),
    ("speed_mps", "float4[]"),
    ("accel_mps2", "float4[]"),
    ("heading_deg", "float4[]"),
    ("lane", "int2[]"),
    ("x_m", "float4[]"),
    ("is_acc_engaged", "bool[]"),
    ("is_controller_engaged", "bool[]"),
    ("controller", "text[]"),
    ("acc_speed_setting_mph", "float4[]"),
    ("acc_gap_setting", "int2[]"),
    ("is_lead_present", "bool[]"),
    ("lead_distance_m", "float4[]"),
    ("lead_rel_speed_mps", "float4[]"),
    ("plan_id", "int8[]"),
)

INSERT_PINGS = (
    "INSERT INTO fact_vehicle_ping ("
    + ", ".join(name for name, _ in PING_COLUMNS)
    + ")\nSELECT * FROM unnest(\n    "
    + ",\n    ".join(f"%({name})s::{array_type}" for name, array_type in PING_COLUMNS)
    + "\n)\nON CONFLICT (vehicle_id, ts) DO NOTHING\nRETURNING vehicle_id, ts"
)
