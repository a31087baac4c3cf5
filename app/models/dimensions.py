"""Dimensions of the star schema: corridors, road segments (INRIX and fine), vehicles.

Dimensions are small and change rarely; in a sharded deployment they become reference tables
copied to every node (see docs/operations.md).
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from sqlalchemy import (
    CheckConstraint,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    SmallInteger,
    Text,
    UniqueConstraint,
    func,
    text,
)
from sqlalchemy.dialects.postgresql import JSONB
from sqlalchemy.orm import Mapped, mapped_column

from app.models.base import Base, created_at_column


class Corridor(Base):
    """A directed stretch of road: x_m grows along travel, lanes count from the left (1)."""

    __tablename__ = "dim_corridor"
    __table_args__ = (
        CheckConstraint("lanes BETWEEN 1 AND 12", name="lanes_range"),
        CheckConstraint(
            "min_target_speed_mps > 0 AND min_target_speed_mps < speed_limit_mps",
            name="legal_speed_range",
        ),
        {"comment": "One row per corridor (directed road stretch) the fleet drives."},
    )

    corridor_id: Mapped[str] = mapped_column(Text, primary_key=True)
    name: Mapped[str] = mapped_column(Text)
    direction: Mapped[str] = mapped_column(Text)
    lanes: Mapped[int] = mapped_column(SmallInteger)
    length_m: Mapped[float] = mapped_column(Float)
    # The legal range every planned target is clipped to (paper: targets within posted limits).
    speed_limit_mps: Mapped[float] = mapped_column(Float)
    min_target_speed_mps: Mapped[float] = mapped_column(Float)
    postmile_at_start: Mapped[float] = mapped_column(Float, server_default=text("0"))
    created_at: Mapped[datetime] = created_at_column()


class InrixSegment(Base):
    """An INRIX XD segment (~0.5 mi): the grain of the third-party speed feed."""

    __tablename__ = "dim_inrix_segment"
    __table_args__ = (
        UniqueConstraint("corridor_id", "seq"),
        CheckConstraint("end_x_m > start_x_m", name="positive_length"),
        {"comment": "One row per INRIX XD segment on a corridor, in order of travel."},
    )

    xd_code: Mapped[str] = mapped_column(Text, primary_key=True)
    corridor_id: Mapped[str] = mapped_column(ForeignKey("dim_corridor.corridor_id"))
    seq: Mapped[int] = mapped_column(SmallInteger)
    start_x_m: Mapped[float] = mapped_column(Float)
    end_x_m: Mapped[float] = mapped_column(Float)
    length_m: Mapped[float] = mapped_column(Float)
    start_postmile: Mapped[float] = mapped_column(Float)
    end_postmile: Mapped[float] = mapped_column(Float)
    lanes: Mapped[int] = mapped_column(SmallInteger)
    start_lat: Mapped[float] = mapped_column(Float)
    start_lon: Mapped[float] = mapped_column(Float)
    end_lat: Mapped[float] = mapped_column(Float)
    end_lon: Mapped[float] = mapped_column(Float)


class I24Segment(Base):
    """A fine sub-segment (<= 200 m) of an INRIX segment: the planner's spatial grid."""

    __tablename__ = "dim_i24_segment"
    __table_args__ = (
        UniqueConstraint("corridor_id", "seq"),
        CheckConstraint("end_x_m > start_x_m AND end_x_m - start_x_m <= 200", name="length_range"),
        {"comment": "One row per fine sub-segment (<= 200 m) the Speed Planner works on."},
    )

    i24_segment_id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=False)
    corridor_id: Mapped[str] = mapped_column(ForeignKey("dim_corridor.corridor_id"))
    seq: Mapped[int] = mapped_column(Integer)
    xd_code: Mapped[str] = mapped_column(ForeignKey("dim_inrix_segment.xd_code"))
    start_x_m: Mapped[float] = mapped_column(Float)
    end_x_m: Mapped[float] = mapped_column(Float)
    start_postmile: Mapped[float] = mapped_column(Float)
    end_postmile: Mapped[float] = mapped_column(Float)
    lanes: Mapped[int] = mapped_column(SmallInteger)
    start_lat: Mapped[float] = mapped_column(Float)
    start_lon: Mapped[float] = mapped_column(Float)
    end_lat: Mapped[float] = mapped_column(Float)
    end_lon: Mapped[float] = mapped_column(Float)


class Vehicle(Base):
    """A car of the fleet: what it is, how it is actuated, where and how it should drive."""

    __tablename__ = "dim_vehicle"
    __table_args__ = (
        CheckConstraint("actuation IN ('acc', 'accel')", name="actuation_kind"),
        CheckConstraint("year BETWEEN 1990 AND 2100", name="year_range"),
        CheckConstraint("assigned_lane >= 1", name="lane_positive"),
        CheckConstraint("vehicle_id ~ '^[A-Za-z0-9_-]{1,32}$'", name="vehicle_id_format"),
        {"comment": "One row per fleet vehicle (roster id)."},
    )

    vehicle_id: Mapped[str] = mapped_column(Text, primary_key=True)
    vin: Mapped[str] = mapped_column(Text, unique=True)
    make: Mapped[str] = mapped_column(Text)
    model: Mapped[str] = mapped_column(Text)
    year: Mapped[int] = mapped_column(SmallInteger)
    actuation: Mapped[str] = mapped_column(Text)
    corridor_id: Mapped[str] = mapped_column(ForeignKey("dim_corridor.corridor_id"))
    route: Mapped[str] = mapped_column(Text)
    assigned_lane: Mapped[int] = mapped_column(SmallInteger)
    controller_name: Mapped[str] = mapped_column(Text)
    controller_params: Mapped[dict[str, Any]] = mapped_column(
        JSONB, server_default=text("'{}'::jsonb")
    )
    is_active: Mapped[bool] = mapped_column(server_default=text("true"))
    is_in_maintenance: Mapped[bool] = mapped_column(server_default=text("false"))
    maintenance_note: Mapped[str | None] = mapped_column(Text)
    # Bumped by every change of what the car should run; the agent echoes the one it applied.
    config_version: Mapped[int] = mapped_column(Integer, server_default=text("1"))
    created_at: Mapped[datetime] = created_at_column()
    updated_at: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), server_default=func.now(), onupdate=func.now()
    )


class VehicleAssignment(Base):
    """A vehicle's corridor, route and lane over a span of time (slowly changing, type 2).

    `dim_vehicle` holds what a car is assigned now; this table what it was assigned when, so a
    ping is read against the assignment in force at its ts (the analytics views join on
    `valid_from <= ts < valid_to`). A trigger on dim_vehicle writes it (migration 0012), in the
    transaction of the change and only when corridor, route or lane actually change: no code
    writes it directly. A vehicle's first row starts at -infinity (a ping's ts is the car's
    clock and may precede the server's row); the open row has valid_to = infinity. psycopg
    loads no infinite timestamp into a `datetime`: read the ends with `isfinite()` in SQL.
    """

    __tablename__ = "dim_vehicle_assignment"
    __table_args__ = (
        CheckConstraint("valid_from < valid_to", name="span_positive"),
        CheckConstraint("assigned_lane >= 1", name="lane_positive"),
        # One open (current) row per vehicle.
        Index(
            "ix_dim_vehicle_assignment_vehicle_id",
            "vehicle_id",
            unique=True,
            postgresql_where=text("valid_to = 'infinity'::timestamptz"),
        ),
        {
            "comment": "One row per vehicle per assignment (corridor, route, lane), in force "
            "over [valid_from, valid_to); the current one has valid_to = infinity."
        },
    )

    vehicle_id: Mapped[str] = mapped_column(
        ForeignKey("dim_vehicle.vehicle_id", ondelete="CASCADE"), primary_key=True
    )
    valid_from: Mapped[datetime] = mapped_column(DateTime(timezone=True), primary_key=True)
    valid_to: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), server_default=text("'infinity'")
    )
    corridor_id: Mapped[str] = mapped_column(ForeignKey("dim_corridor.corridor_id"))
    route: Mapped[str] = mapped_column(Text)
    assigned_lane: Mapped[int] = mapped_column(SmallInteger)


class Policy(Base):
    """A trained controller policy (the `.npz` a car evaluates), stored by its sha256.

    The bytes live in the database beside their manifest: a policy is tens of kB, so one row
    holds both, they commit together (never a row without its file, or a file without its
    row), and every copy of the database (backup, replica, the next server host) carries them;
    a directory under the data dir would have to be shared by every server host and kept in
    step by hand. A car's assignment names a policy by `policy_sha256`; its pings and status
    reports carry the hash it runs.
    """

    __tablename__ = "dim_policy"
    __table_args__ = (
        CheckConstraint("policy_sha256 ~ '^[0-9a-f]{64}$'", name="sha256_format"),
        CheckConstraint("controller IN ('rl_acc', 'rl_accel')", name="controller_kind"),
        CheckConstraint("octet_length(content) = size_bytes", name="size_matches"),
        {"comment": "One row per policy artefact (file bytes + manifest), keyed by its sha256."},
    )

    policy_sha256: Mapped[str] = mapped_column(Text, primary_key=True)
    controller: Mapped[str] = mapped_column(Text)
    manifest: Mapped[dict[str, Any]] = mapped_column(JSONB)
    # Deferred: listing policies never reads the files.
    content: Mapped[bytes] = mapped_column(LargeBinary, deferred=True)
    size_bytes: Mapped[int] = mapped_column(Integer)
    uploaded_by: Mapped[str] = mapped_column(Text)
    uploaded_at: Mapped[datetime] = created_at_column()
