"""The star schema of the paper's server side, plus access tables and ping partitioning.

Revision ID: 0001
Revises:
Create Date: 2026-11-23 09:22:27.711388+00:00

fact_vehicle_ping is range-partitioned by UTC day of ts. ensure_ping_partitions() creates the
daily partitions ahead of time (the server calls it at start-up and every hour, and this
migration calls it once); a DEFAULT partition catches anything outside them so no insert ever
fails for want of a partition, and the next ensure_ping_partitions() moves those rows into their
day's partition when it creates that day's (from yesterday on; app/maintenance.py deletes the
older ones past retention). drop_ping_partitions_before() implements the retention setting.
"""

from collections.abc import Sequence

import sqlalchemy as sa
from alembic import op
from sqlalchemy.dialects import postgresql

revision: str = "0001"
down_revision: str | None = None
branch_labels: str | Sequence[str] | None = None
depends_on: str | Sequence[str] | None = None


PING_PARTITION_FUNCTIONS = """
CREATE FUNCTION ping_partition_name(day date) RETURNS text
LANGUAGE sql IMMUTABLE AS $$
    SELECT 'fact_vehicle_ping_p' || to_char(day, 'YYYYMMDD')
$$;

CREATE FUNCTION ensure_ping_partitions(first_day date, last_day date) RETURNS integer
LANGUAGE plpgsql AS $$
DECLARE
    day date;
    part text;
    lower_bound timestamptz;
    upper_bound timestamptz;
    created integer := 0;
BEGIN
    FOR day IN SELECT generate_series(first_day, last_day, interval '1 day')::date LOOP
        part := ping_partition_name(day);
        CONTINUE WHEN to_regclass(part) IS NOT NULL;
        lower_bound := day::timestamp AT TIME ZONE 'UTC';
        upper_bound := (day + 1)::timestamp AT TIME ZONE 'UTC';
        EXECUTE format(
            'CREATE TABLE %I (LIKE fact_vehicle_ping INCLUDING DEFAULTS INCLUDING CONSTRAINTS)',
            part);
        -- Rows of this day that arrived before its partition existed wait in the default one.
        EXECUTE format(
            'WITH moved AS (DELETE FROM fact_vehicle_ping_default WHERE ts >= %L AND ts < %L '
            'RETURNING *) INSERT INTO %I SELECT * FROM moved',
            lower_bound, upper_bound, part);
        EXECUTE format(
            'ALTER TABLE fact_vehicle_ping ATTACH PARTITION %I FOR VALUES FROM (%L) TO (%L)',
            part, lower_bound, upper_bound);
        created := created + 1;
    END LOOP;
    RETURN created;
END
$$;

CREATE FUNCTION drop_ping_partitions_before(cutoff date) RETURNS integer
LANGUAGE plpgsql AS $$
DECLARE
    part record;
    dropped integer := 0;
BEGIN
    FOR part IN
        SELECT child.relname
        FROM pg_inherits
        JOIN pg_class parent ON parent.oid = pg_inherits.inhparent
        JOIN pg_class child ON child.oid = pg_inherits.inhrelid
        WHERE parent.relname = 'fact_vehicle_ping'
          AND child.relname ~ '^fact_vehicle_ping_p[0-9]{8}$'
          AND to_date(right(child.relname, 8), 'YYYYMMDD') < cutoff
    LOOP
        EXECUTE format('DROP TABLE %I', part.relname);
        dropped := dropped + 1;
    END LOOP;
    RETURN dropped;
END
$$;
"""


def upgrade() -> None:
    op.create_table(
        "dim_corridor",
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("name", sa.Text(), nullable=False),
        sa.Column("direction", sa.Text(), nullable=False),
        sa.Column("lanes", sa.SmallInteger(), nullable=False),
        sa.Column("length_m", sa.Float(), nullable=False),
        sa.Column("speed_limit_mps", sa.Float(), nullable=False),
        sa.Column("min_target_speed_mps", sa.Float(), nullable=False),
        sa.Column("postmile_at_start", sa.Float(), server_default=sa.text("0"), nullable=False),
        sa.Column(
            "created_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.CheckConstraint("lanes BETWEEN 1 AND 12", name=op.f("ck_dim_corridor_lanes_range")),
        sa.CheckConstraint(
            "min_target_speed_mps > 0 AND min_target_speed_mps < speed_limit_mps",
            name=op.f("ck_dim_corridor_legal_speed_range"),
        ),
        sa.PrimaryKeyConstraint("corridor_id", name=op.f("pk_dim_corridor")),
        comment="One row per corridor (directed road stretch) the fleet drives.",
    )
    op.create_table(
        "ops_user",
        sa.Column("username", sa.Text(), nullable=False),
        sa.Column("password_hash", sa.Text(), nullable=False),
        sa.Column("role", sa.Text(), nullable=False),
        sa.Column("failed_logins", sa.Integer(), server_default=sa.text("0"), nullable=False),
        sa.Column("last_failed_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("last_login_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column(
            "created_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.CheckConstraint(
            "role IN ('viewer', 'operator', 'admin')", name=op.f("ck_ops_user_role_kind")
        ),
        sa.PrimaryKeyConstraint("username", name=op.f("pk_ops_user")),
        comment="One row per dashboard user; password_hash is a salted scrypt hash.",
    )
    op.create_table(
        "dim_inrix_segment",
        sa.Column("xd_code", sa.Text(), nullable=False),
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("seq", sa.SmallInteger(), nullable=False),
        sa.Column("start_x_m", sa.Float(), nullable=False),
        sa.Column("end_x_m", sa.Float(), nullable=False),
        sa.Column("length_m", sa.Float(), nullable=False),
        sa.Column("start_postmile", sa.Float(), nullable=False),
        sa.Column("end_postmile", sa.Float(), nullable=False),
        sa.Column("lanes", sa.SmallInteger(), nullable=False),
        sa.Column("start_lat", sa.Float(), nullable=False),
        sa.Column("start_lon", sa.Float(), nullable=False),
        sa.Column("end_lat", sa.Float(), nullable=False),
        sa.Column("end_lon", sa.Float(), nullable=False),
        sa.CheckConstraint(
            "end_x_m > start_x_m", name=op.f("ck_dim_inrix_segment_positive_length")
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_dim_inrix_segment_corridor_id_dim_corridor"),
        ),
        sa.PrimaryKeyConstraint("xd_code", name=op.f("pk_dim_inrix_segment")),
        sa.UniqueConstraint(
            "corridor_id", "seq", name=op.f("uq_dim_inrix_segment_corridor_id_seq")
        ),
        comment="One row per INRIX XD segment on a corridor, in order of travel.",
    )
    op.create_table(
        "dim_vehicle",
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("vin", sa.Text(), nullable=False),
        sa.Column("make", sa.Text(), nullable=False),
        sa.Column("model", sa.Text(), nullable=False),
        sa.Column("year", sa.SmallInteger(), nullable=False),
        sa.Column("actuation", sa.Text(), nullable=False),
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("route", sa.Text(), nullable=False),
        sa.Column("assigned_lane", sa.SmallInteger(), nullable=False),
        sa.Column("controller_name", sa.Text(), nullable=False),
        sa.Column(
            "controller_params",
            postgresql.JSONB(astext_type=sa.Text()),
            server_default=sa.text("'{}'::jsonb"),
            nullable=False,
        ),
        sa.Column("is_active", sa.Boolean(), server_default=sa.text("true"), nullable=False),
        sa.Column(
            "is_in_maintenance", sa.Boolean(), server_default=sa.text("false"), nullable=False
        ),
        sa.Column("maintenance_note", sa.Text(), nullable=True),
        sa.Column(
            "created_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column(
            "updated_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.CheckConstraint(
            "actuation IN ('acc', 'accel')", name=op.f("ck_dim_vehicle_actuation_kind")
        ),
        sa.CheckConstraint(
            "vehicle_id ~ '^[A-Za-z0-9_-]{1,32}$'", name=op.f("ck_dim_vehicle_vehicle_id_format")
        ),
        sa.CheckConstraint("assigned_lane >= 1", name=op.f("ck_dim_vehicle_lane_positive")),
        sa.CheckConstraint("year BETWEEN 1990 AND 2100", name=op.f("ck_dim_vehicle_year_range")),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_dim_vehicle_corridor_id_dim_corridor"),
        ),
        sa.PrimaryKeyConstraint("vehicle_id", name=op.f("pk_dim_vehicle")),
        sa.UniqueConstraint("vin", name=op.f("uq_dim_vehicle_vin")),
        comment="One row per fleet vehicle (roster id).",
    )
    op.create_table(
        "plan_run",
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("plan_id", sa.BigInteger(), sa.Identity(always=False), nullable=False),
        sa.Column("status", sa.Text(), nullable=False),
        sa.Column("reason", sa.Text(), nullable=True),
        sa.Column("algorithm", sa.Text(), nullable=False),
        sa.Column(
            "params",
            postgresql.JSONB(astext_type=sa.Text()),
            server_default=sa.text("'{}'::jsonb"),
            nullable=False,
        ),
        sa.Column(
            "inputs",
            postgresql.JSONB(astext_type=sa.Text()),
            server_default=sa.text("'{}'::jsonb"),
            nullable=False,
        ),
        sa.Column("started_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column("published_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("valid_until", sa.DateTime(timezone=True), nullable=True),
        sa.Column("duration_ms", sa.Float(), nullable=True),
        sa.CheckConstraint(
            "(status = 'published') = (published_at IS NOT NULL AND valid_until IS NOT NULL)",
            name=op.f("ck_plan_run_published_has_times"),
        ),
        sa.CheckConstraint(
            "status IN ('published', 'skipped', 'failed')", name=op.f("ck_plan_run_status_kind")
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_plan_run_corridor_id_dim_corridor"),
        ),
        sa.PrimaryKeyConstraint("corridor_id", "plan_id", name=op.f("pk_plan_run")),
        comment="One row per planner run per corridor (published, skipped or failed).",
    )
    op.create_index(
        "ix_plan_run_corridor_id_published_at",
        "plan_run",
        ["corridor_id", "published_at"],
        unique=False,
        postgresql_where=sa.text("status = 'published'"),
    )
    op.create_index("ix_plan_run_plan_id", "plan_run", ["plan_id"], unique=False)
    op.create_table(
        "api_token",
        sa.Column("token_id", sa.BigInteger(), sa.Identity(always=False), nullable=False),
        sa.Column("kind", sa.Text(), nullable=False),
        sa.Column("role", sa.Text(), nullable=True),
        sa.Column("vehicle_id", sa.Text(), nullable=True),
        sa.Column("name", sa.Text(), server_default=sa.text("''"), nullable=False),
        sa.Column("token_hash", sa.Text(), nullable=False),
        sa.Column(
            "created_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column("revoked_at", sa.DateTime(timezone=True), nullable=True),
        sa.Column("last_used_at", sa.DateTime(timezone=True), nullable=True),
        sa.CheckConstraint(
            "(kind = 'ops') = (role IS NOT NULL)", name=op.f("ck_api_token_ops_role")
        ),
        sa.CheckConstraint(
            "(kind = 'vehicle') = (vehicle_id IS NOT NULL)",
            name=op.f("ck_api_token_vehicle_binding"),
        ),
        sa.CheckConstraint(
            "kind IN ('vehicle', 'feed', 'ops')", name=op.f("ck_api_token_token_kind")
        ),
        sa.CheckConstraint(
            "role IS NULL OR role IN ('viewer', 'operator', 'admin')",
            name=op.f("ck_api_token_role_kind"),
        ),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_api_token_vehicle_id_dim_vehicle"),
            ondelete="CASCADE",
        ),
        sa.PrimaryKeyConstraint("token_id", name=op.f("pk_api_token")),
        sa.UniqueConstraint("token_hash", name=op.f("uq_api_token_token_hash")),
        comment="One row per issued bearer token; token_hash = sha256(token) hex.",
    )
    op.create_index(op.f("ix_api_token_vehicle_id"), "api_token", ["vehicle_id"], unique=False)
    op.create_table(
        "dim_i24_segment",
        sa.Column("i24_segment_id", sa.Integer(), autoincrement=False, nullable=False),
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("seq", sa.Integer(), nullable=False),
        sa.Column("xd_code", sa.Text(), nullable=False),
        sa.Column("start_x_m", sa.Float(), nullable=False),
        sa.Column("end_x_m", sa.Float(), nullable=False),
        sa.Column("start_postmile", sa.Float(), nullable=False),
        sa.Column("end_postmile", sa.Float(), nullable=False),
        sa.Column("lanes", sa.SmallInteger(), nullable=False),
        sa.Column("start_lat", sa.Float(), nullable=False),
        sa.Column("start_lon", sa.Float(), nullable=False),
        sa.Column("end_lat", sa.Float(), nullable=False),
        sa.Column("end_lon", sa.Float(), nullable=False),
        sa.CheckConstraint(
            "end_x_m > start_x_m AND end_x_m - start_x_m <= 200",
            name=op.f("ck_dim_i24_segment_length_range"),
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_dim_i24_segment_corridor_id_dim_corridor"),
        ),
        sa.ForeignKeyConstraint(
            ["xd_code"],
            ["dim_inrix_segment.xd_code"],
            name=op.f("fk_dim_i24_segment_xd_code_dim_inrix_segment"),
        ),
        sa.PrimaryKeyConstraint("i24_segment_id", name=op.f("pk_dim_i24_segment")),
        sa.UniqueConstraint("corridor_id", "seq", name=op.f("uq_dim_i24_segment_corridor_id_seq")),
        comment="One row per fine sub-segment (<= 200 m) the Speed Planner works on.",
    )
    op.create_table(
        "fact_inrix_estimate",
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("xd_code", sa.Text(), nullable=False),
        sa.Column("measured_at", sa.DateTime(timezone=True), nullable=False),
        sa.Column(
            "received_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column("speed_mps", sa.REAL(), nullable=True),
        sa.Column("average_speed_mps", sa.REAL(), nullable=True),
        sa.Column("reference_speed_mps", sa.REAL(), nullable=True),
        sa.Column("travel_time_s", sa.REAL(), nullable=True),
        sa.Column("score", sa.SmallInteger(), nullable=True),
        sa.Column("c_value", sa.REAL(), nullable=True),
        sa.Column("is_closed", sa.Boolean(), server_default=sa.text("false"), nullable=False),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_fact_inrix_estimate_corridor_id_dim_corridor"),
        ),
        sa.ForeignKeyConstraint(
            ["xd_code"],
            ["dim_inrix_segment.xd_code"],
            name=op.f("fk_fact_inrix_estimate_xd_code_dim_inrix_segment"),
        ),
        sa.PrimaryKeyConstraint(
            "corridor_id", "xd_code", "measured_at", name=op.f("pk_fact_inrix_estimate")
        ),
        comment="One row per INRIX segment per provider timestamp (measured_at).",
    )
    op.create_index(
        "ix_fact_inrix_estimate_corridor_id_measured_at",
        "fact_inrix_estimate",
        ["corridor_id", "measured_at"],
        unique=False,
    )
    op.create_table(
        "fact_vehicle_ping",
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("ts", sa.DateTime(timezone=True), nullable=False),
        sa.Column(
            "received_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column("lat", sa.Float(), nullable=False),
        sa.Column("lon", sa.Float(), nullable=False),
        sa.Column("speed_mps", sa.REAL(), nullable=False),
        sa.Column("accel_mps2", sa.REAL(), nullable=True),
        sa.Column("heading_deg", sa.REAL(), nullable=True),
        sa.Column("lane", sa.SmallInteger(), nullable=True),
        sa.Column("x_m", sa.REAL(), nullable=True),
        sa.Column("is_acc_engaged", sa.Boolean(), nullable=True),
        sa.Column("is_controller_engaged", sa.Boolean(), nullable=True),
        sa.Column("controller", sa.Text(), nullable=True),
        sa.Column("acc_speed_setting_mph", sa.REAL(), nullable=True),
        sa.Column("acc_gap_setting", sa.SmallInteger(), nullable=True),
        sa.Column("is_lead_present", sa.Boolean(), nullable=True),
        sa.Column("lead_distance_m", sa.REAL(), nullable=True),
        sa.Column("lead_rel_speed_mps", sa.REAL(), nullable=True),
        sa.Column("plan_id", sa.BigInteger(), nullable=True),
        sa.CheckConstraint(
            "acc_gap_setting BETWEEN 1 AND 3", name=op.f("ck_fact_vehicle_ping_gap_setting_range")
        ),
        sa.CheckConstraint(
            "lat BETWEEN -90 AND 90 AND lon BETWEEN -180 AND 180",
            name=op.f("ck_fact_vehicle_ping_on_globe"),
        ),
        sa.CheckConstraint(
            "speed_mps >= 0 AND speed_mps <= 90", name=op.f("ck_fact_vehicle_ping_speed_range")
        ),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_fact_vehicle_ping_vehicle_id_dim_vehicle"),
        ),
        sa.PrimaryKeyConstraint("vehicle_id", "ts", name=op.f("pk_fact_vehicle_ping")),
        comment="One row per vehicle per GPS timestamp (ts); partitioned by UTC day of ts.",
        postgresql_partition_by="RANGE (ts)",
    )
    op.create_index("ix_fact_vehicle_ping_ts", "fact_vehicle_ping", ["ts"], unique=False)
    op.execute("CREATE TABLE fact_vehicle_ping_default PARTITION OF fact_vehicle_ping DEFAULT")
    op.execute(PING_PARTITION_FUNCTIONS)
    op.execute("SELECT ensure_ping_partitions(current_date - 1, current_date + 7)")
    op.create_table(
        "fact_vehicle_status",
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("ts", sa.DateTime(timezone=True), nullable=False),
        sa.Column(
            "received_at",
            sa.DateTime(timezone=True),
            server_default=sa.text("now()"),
            nullable=False,
        ),
        sa.Column("agent_version", sa.Text(), nullable=True),
        sa.Column("uptime_s", sa.Float(), nullable=True),
        sa.Column("is_can_ok", sa.Boolean(), nullable=True),
        sa.Column("can_msgs_per_s", sa.REAL(), nullable=True),
        sa.Column("has_gps_fix", sa.Boolean(), nullable=True),
        sa.Column("gps_satellites", sa.SmallInteger(), nullable=True),
        sa.Column("is_acc_available", sa.Boolean(), nullable=True),
        sa.Column("controller", sa.Text(), nullable=True),
        sa.Column("is_controller_running", sa.Boolean(), nullable=True),
        sa.Column("plan_id", sa.BigInteger(), nullable=True),
        sa.Column("plan_age_s", sa.REAL(), nullable=True),
        sa.Column("spool_backlog", sa.Integer(), nullable=True),
        sa.Column("disk_free_mb", sa.REAL(), nullable=True),
        sa.Column("cpu_temp_c", sa.REAL(), nullable=True),
        sa.Column("is_ups_on_battery", sa.Boolean(), nullable=True),
        sa.Column("server_rtt_ms", sa.REAL(), nullable=True),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_fact_vehicle_status_vehicle_id_dim_vehicle"),
        ),
        sa.PrimaryKeyConstraint("vehicle_id", "ts", name=op.f("pk_fact_vehicle_status")),
        comment="One row per vehicle per status report (ts of the report).",
    )
    op.create_table(
        "fact_speed_planner",
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("plan_id", sa.BigInteger(), nullable=False),
        sa.Column("lane", sa.SmallInteger(), nullable=False),
        sa.Column("i24_segment_id", sa.Integer(), nullable=False),
        sa.Column("target_speed_mps", sa.REAL(), nullable=False),
        sa.Column("is_buffer", sa.Boolean(), server_default=sa.text("false"), nullable=False),
        sa.Column("tse_speed_mps", sa.REAL(), nullable=True),
        sa.Column("smoothed_speed_mps", sa.REAL(), nullable=True),
        sa.CheckConstraint(
            "target_speed_mps >= 0", name=op.f("ck_fact_speed_planner_target_nonnegative")
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id", "plan_id"],
            ["plan_run.corridor_id", "plan_run.plan_id"],
            name=op.f("fk_fact_speed_planner_corridor_id_plan_id_plan_run"),
            ondelete="CASCADE",
        ),
        sa.ForeignKeyConstraint(
            ["i24_segment_id"],
            ["dim_i24_segment.i24_segment_id"],
            name=op.f("fk_fact_speed_planner_i24_segment_id_dim_i24_segment"),
        ),
        sa.PrimaryKeyConstraint(
            "corridor_id", "plan_id", "lane", "i24_segment_id", name=op.f("pk_fact_speed_planner")
        ),
        comment="One row per plan run per lane per sub-segment.",
    )
    op.create_table(
        "fact_vehicle_observation",
        sa.Column("vehicle_id", sa.Text(), nullable=False),
        sa.Column("window_end", sa.DateTime(timezone=True), nullable=False),
        sa.Column("i24_segment_id", sa.Integer(), nullable=False),
        sa.Column("lane", sa.SmallInteger(), nullable=False),
        sa.Column("window_start", sa.DateTime(timezone=True), nullable=False),
        sa.Column("corridor_id", sa.Text(), nullable=False),
        sa.Column("mean_speed_mps", sa.REAL(), nullable=False),
        sa.Column("ping_count", sa.Integer(), nullable=False),
        sa.CheckConstraint("ping_count > 0", name=op.f("ck_fact_vehicle_observation_has_pings")),
        sa.CheckConstraint(
            "window_end > window_start", name=op.f("ck_fact_vehicle_observation_window_order")
        ),
        sa.ForeignKeyConstraint(
            ["corridor_id"],
            ["dim_corridor.corridor_id"],
            name=op.f("fk_fact_vehicle_observation_corridor_id_dim_corridor"),
        ),
        sa.ForeignKeyConstraint(
            ["i24_segment_id"],
            ["dim_i24_segment.i24_segment_id"],
            name=op.f("fk_fact_vehicle_observation_i24_segment_id_dim_i24_segment"),
        ),
        sa.ForeignKeyConstraint(
            ["vehicle_id"],
            ["dim_vehicle.vehicle_id"],
            name=op.f("fk_fact_vehicle_observation_vehicle_id_dim_vehicle"),
        ),
        sa.PrimaryKeyConstraint(
            "vehicle_id",
            "window_end",
            "i24_segment_id",
            "lane",
            name=op.f("pk_fact_vehicle_observation"),
        ),
        comment="One row per vehicle per planner window per sub-segment and lane it drove in "
        "(mean of its pings there).",
    )
    op.create_index(
        "ix_fact_vehicle_observation_corridor_id_window_end",
        "fact_vehicle_observation",
        ["corridor_id", "window_end"],
        unique=False,
    )


def downgrade() -> None:
    op.drop_index(
        "ix_fact_vehicle_observation_corridor_id_window_end", table_name="fact_vehicle_observation"
    )
    op.drop_table("fact_vehicle_observation")
    op.drop_table("fact_speed_planner")
    op.drop_table("fact_vehicle_status")
    op.execute("DROP FUNCTION drop_ping_partitions_before(date)")
    op.execute("DROP FUNCTION ensure_ping_partitions(date, date)")
    op.execute("DROP FUNCTION ping_partition_name(date)")
    op.drop_index("ix_fact_vehicle_ping_ts", table_name="fact_vehicle_ping")
    op.drop_table("fact_vehicle_ping")
    op.drop_index(
        "ix_fact_inrix_estimate_corridor_id_measured_at", table_name="fact_inrix_estimate"
    )
    op.drop_table("fact_inrix_estimate")
    op.drop_table("dim_i24_segment")
    op.drop_index(op.f("ix_api_token_vehicle_id"), table_name="api_token")
    op.drop_table("api_token")
    op.drop_index("ix_plan_run_plan_id", table_name="plan_run")
    op.drop_index(
        "ix_plan_run_corridor_id_published_at",
        table_name="plan_run",
        postgresql_where=sa.text("status = 'published'"),
    )
    op.drop_table("plan_run")
    op.drop_table("dim_vehicle")
    op.drop_table("dim_inrix_segment")
    op.drop_table("ops_user")
    op.drop_table("dim_corridor")
