"""Facts of the star schema (the paper's "Server-side implementation" tables).

Every fact table states its grain, enforces its key, references its dimensions, and has its
distribution column (vehicle_id or corridor_id) in its key so it can be sharded later.
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    REAL,
    BigInteger,
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    ForeignKeyConstraint,
    Identity,
    Index,
    Integer,
    SmallInteger,
    Text,
    func,
    text,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import Mapped, mapped_column

from app.models.base import Base

PING_GRAIN = "One row per vehicle per GPS timestamp (ts); partitioned by UTC day of ts."


def received_at_column() -> Mapped[datetime]:
    """When the server accepted the row (ts is the vehicle's own GPS clock)."""
    return mapped_column(DateTime(timezone=True), server_default=func.now())


class VehiclePing(Base):
    """A vehicle's 1 Hz ping (paper: fact_vehicle_ping)."""

    __tablename__ = "fact_vehicle_ping"
    __table_args__ = (
        CheckConstraint("speed_mps >= 0 AND speed_mps <= 90", name="speed_range"),
        CheckConstraint("lat BETWEEN -90 AND 90 AND lon BETWEEN -180 AND 180", name="on_globe"),
        CheckConstraint("acc_gap_setting BETWEEN 1 AND 3", name="gap_setting_range"),
        Index("ix_fact_vehicle_ping_ts", "ts"),
        {"comment": PING_GRAIN, "postgresql_partition_by": "RANGE (ts)"},
    )

    vehicle_id: Mapped[str] = mapped_column(ForeignKey("dim_vehicle.vehicle_id"), primary_key=True)
    ts: Mapped[datetime] = mapped_column(DateTime(timezone=True), primary_key=True)
    received_at: Mapped[datetime] = received_at_column()
    lat: Mapped[float] = mapped_column(Float)
    lon: Mapped[float] = mapped_column(Float)
    speed_mps: Mapped[float] = mapped_column(REAL)
    accel_mps2: Mapped[float | None] = mapped_column(REAL)
    heading_deg: Mapped[float | None] = mapped_column(REAL)
    lane: Mapped[int | None] = mapped_column(SmallInteger)
    # Position along the vehicle's corridor, map-matched at ingest; NULL when off the corridor.
    x_m: Mapped[float | None] = mapped_column(REAL)
    is_acc_engaged: Mapped[bool | None]
    is_controller_engaged: Mapped[bool | None]
    controller: Mapped[str | None] = mapped_column(Text)
    acc_speed_setting_mph: Mapped[float | None] = mapped_column(REAL)
    acc_gap_setting: Mapped[int | None] = mapped_column(SmallInteger)
    is_lead_present: Mapped[bool | None]
    lead_distance_m: Mapped[float | None] = mapped_column(REAL)
    lead_rel_speed_mps: Mapped[float | None] = mapped_column(REAL)
    # The plan being followed; no foreign key so ingest never waits on plan_run locks.
    plan_id: Mapped[int | None] = mapped_column(BigInteger)
    # The sha256 of the policy the controller ran (RL controllers); no foreign key, so a ping
    # naming a policy the server does not hold (a car's bundled one) is still stored.
    policy_sha256: Mapped[str | None] = mapped_column(Text)


class VehicleStatus(Base):
    """A piStatus report: the health of a car's computer, CAN, GPS and agent."""

    __tablename__ = "fact_vehicle_status"
    __table_args__ = (
        Index("ix_fact_vehicle_status_ts", "ts"),
        {"comment": "One row per vehicle per status report (ts of the report)."},
    )

    vehicle_id: Mapped[str] = mapped_column(ForeignKey("dim_vehicle.vehicle_id"), primary_key=True)
    ts: Mapped[datetime] = mapped_column(DateTime(timezone=True), primary_key=True)
    received_at: Mapped[datetime] = received_at_column()
    agent_version: Mapped[str | None] = mapped_column(Text)
    uptime_s: Mapped[float | None] = mapped_column(Float)
    is_can_ok: Mapped[bool | None]
    can_msgs_per_s: Mapped[float | None] = mapped_column(REAL)
    has_gps_fix: Mapped[bool | None]
    gps_satellites: Mapped[int | None] = mapped_column(SmallInteger)
    is_acc_available: Mapped[bool | None]
    controller: Mapped[str | None] = mapped_column(Text)
    is_controller_running: Mapped[bool | None]
    plan_id: Mapped[int | None] = mapped_column(BigInteger)
    plan_age_s: Mapped[float | None] = mapped_column(REAL)
    spool_backlog: Mapped[int | None] = mapped_column(Integer)
    spool_dropped: Mapped[int | None] = mapped_column(Integer)
    disk_free_mb: Mapped[float | None] = mapped_column(REAL)
    cpu_temp_c: Mapped[float | None] = mapped_column(REAL)
    is_ups_on_battery: Mapped[bool | None]
    server_rtt_ms: Mapped[float | None] = mapped_column(REAL)
    config_version: Mapped[int | None] = mapped_column(Integer)
    policy_sha256: Mapped[str | None] = mapped_column(Text)
    engage_reason: Mapped[str | None] = mapped_column(Text)


class VehicleChange(Base):
    """A change to a vehicle's assignment or maintenance (API or dashboard), or to its roster
    row (`vehicles import|add`, migration 0023), with who made it and when: the record of each
    car's clearing and reassignment, one row per config version a change produced through the
    code. A change made in SQL (pulling a car: `is_active`) gets its version from migration
    0022's trigger and no row here."""

    __tablename__ = "fact_vehicle_change"
    __table_args__ = (
        CheckConstraint("change IN ('assignment', 'maintenance', 'roster')", name="change_kind"),
        {"comment": "One row per operator's change to a vehicle (the config version it produced)."},
    )

    vehicle_id: Mapped[str] = mapped_column(ForeignKey("dim_vehicle.vehicle_id"), primary_key=True)
    config_version: Mapped[int] = mapped_column(Integer, primary_key=True)
    changed_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), server_default=func.now())
    changed_by: Mapped[str] = mapped_column(Text)
    change: Mapped[str] = mapped_column(Text)
    # what an assignment set
    lane: Mapped[int | None] = mapped_column(SmallInteger)
    route: Mapped[str | None] = mapped_column(Text)
    controller_name: Mapped[str | None] = mapped_column(Text)
    # the controller's parameters (an RL controller's policy_sha256 among them)
    controller_params: Mapped[dict[str, Any] | None] = mapped_column(JSONB)
    # what a maintenance change set
    in_maintenance: Mapped[bool | None]
    note: Mapped[str | None] = mapped_column(Text)
    # what a roster change altered: each roster field it changed, as [before, after] (migration
    # 0024); the lane, route and controller above are what the row set, which alone read a
    # change of the parameters, corridor or actuation as no change
    roster_changed: Mapped[dict[str, list[Any]] | None] = mapped_column(JSONB)


class InrixEstimate(Base):
    """A segment speed from the INRIX feed (speeds converted from mph to m/s at ingest)."""

    __tablename__ = "fact_inrix_estimate"
    __table_args__ = (
        Index("ix_fact_inrix_estimate_corridor_id_measured_at", "corridor_id", "measured_at"),
        {"comment": "One row per INRIX segment per provider timestamp (measured_at)."},
    )

    corridor_id: Mapped[str] = mapped_column(
        ForeignKey("dim_corridor.corridor_id"), primary_key=True
    )
    xd_code: Mapped[str] = mapped_column(ForeignKey("dim_inrix_segment.xd_code"), primary_key=True)
    measured_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), primary_key=True)
    received_at: Mapped[datetime] = received_at_column()
    # When the poller fetched the provider's answer, where it stored it later (a backlog kept
    # through a database outage, a replayed recording); NULL: stored as it arrived.
    fetched_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    speed_mps: Mapped[float | None] = mapped_column(REAL)
    average_speed_mps: Mapped[float | None] = mapped_column(REAL)
    reference_speed_mps: Mapped[float | None] = mapped_column(REAL)
    travel_time_s: Mapped[float | None] = mapped_column(REAL)
    score: Mapped[int | None] = mapped_column(SmallInteger)
    c_value: Mapped[float | None] = mapped_column(REAL)
    is_closed: Mapped[bool] = mapped_column(server_default=text("false"))


class VehicleObservation(Base):
    """A vehicle's mean speed in one sub-segment and lane during one planner window."""

    __tablename__ = "fact_vehicle_observation"
    __table_args__ = (
        CheckConstraint("window_end > window_start", name="window_order"),
        CheckConstraint("ping_count > 0", name="has_pings"),
        Index("ix_fact_vehicle_observation_corridor_id_window_end", "corridor_id", "window_end"),
        {
            "comment": "One row per vehicle per planner window per sub-segment and lane it "
            "drove in (mean of its pings there)."
        },
    )

    vehicle_id: Mapped[str] = mapped_column(ForeignKey("dim_vehicle.vehicle_id"), primary_key=True)
    window_end: Mapped[datetime] = mapped_column(DateTime(timezone=True), primary_key=True)
    i24_segment_id: Mapped[int] = mapped_column(
        ForeignKey("dim_i24_segment.i24_segment_id"), primary_key=True
    )
    lane: Mapped[int] = mapped_column(SmallInteger, primary_key=True)
    window_start: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    corridor_id: Mapped[str] = mapped_column(ForeignKey("dim_corridor.corridor_id"))
    mean_speed_mps: Mapped[float] = mapped_column(REAL)
    ping_count: Mapped[int] = mapped_column(Integer)


class PlanRun(Base):
    """One run of the Speed Planner: what it used, how, and whether it published."""

    __tablename__ = "plan_run"
    __table_args__ = (
        CheckConstraint("status IN ('published', 'skipped', 'failed')", name="status_kind"),
        CheckConstraint(
            "(status = 'published') = (published_at IS NOT NULL AND valid_until IS NOT NULL)",
            name="published_has_times",
        ),
        Index(
            "ix_plan_run_corridor_id_published_at",
            "corridor_id",
            "published_at",
            postgresql_where=text("status = 'published'"),
        ),
        Index("ix_plan_run_plan_id", "plan_id"),
        {"comment": "One row per planner run per corridor (published, skipped or failed)."},
    )

    corridor_id: Mapped[str] = mapped_column(
        ForeignKey("dim_corridor.corridor_id"), primary_key=True
    )
    plan_id: Mapped[int] = mapped_column(BigInteger, Identity(), primary_key=True)
    status: Mapped[str] = mapped_column(Text)
    reason: Mapped[str | None] = mapped_column(Text)
    algorithm: Mapped[str] = mapped_column(Text)
    params: Mapped[dict[str, Any]] = mapped_column(JSONB, server_default=text("'{}'::jsonb"))
    inputs: Mapped[dict[str, Any]] = mapped_column(JSONB, server_default=text("'{}'::jsonb"))
    started_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    published_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    valid_until: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    duration_ms: Mapped[float | None] = mapped_column(Float)


class SpeedPlan(Base):
    """A published target speed for one lane of one sub-segment (paper: fact_speed_planner)."""

    __tablename__ = "fact_speed_planner"
    __table_args__ = (
        ForeignKeyConstraint(
            ["corridor_id", "plan_id"],
            ["plan_run.corridor_id", "plan_run.plan_id"],
            ondelete="CASCADE",
        ),
        CheckConstraint("target_speed_mps >= 0", name="target_nonnegative"),
        {"comment": "One row per plan run per lane per sub-segment."},
    )

    corridor_id: Mapped[str] = mapped_column(Text, primary_key=True)
    plan_id: Mapped[int] = mapped_column(BigInteger, primary_key=True)
    lane: Mapped[int] = mapped_column(SmallInteger, primary_key=True)
    i24_segment_id: Mapped[int] = mapped_column(
        ForeignKey("dim_i24_segment.i24_segment_id"), primary_key=True
    )
    target_speed_mps: Mapped[float] = mapped_column(REAL)
    is_buffer: Mapped[bool] = mapped_column(server_default=text("false"))
    # The fused lane-level TSE and its forward-kernel smoothing behind the target (provenance).
    tse_speed_mps: Mapped[float | None] = mapped_column(REAL)
    smoothed_speed_mps: Mapped[float | None] = mapped_column(REAL)
    # The fleet observation the cycle read for this cell (mean of the window's pings, exact, and
    # their count; NULL where none): a plan replays from these, not from pings arriving later.
    fleet_speed_mps: Mapped[float | None] = mapped_column(Float)
    fleet_ping_count: Mapped[int | None] = mapped_column(Integer)
