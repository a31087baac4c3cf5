"""The schema comes from migrations alone, round-trips, and matches the models."""

from __future__ import annotations

import pytest
from alembic import command
from alembic.script import ScriptDirectory
from sqlalchemy import Engine, text

from app.migrate import (
    UnknownRevision,
    alembic_config,
    check_revision,
    downgrade,
    head_revision,
    upgrade,
)

FACT_KEYS = {
    # table: (primary key columns in order, distribution column)
    "fact_vehicle_ping": (["vehicle_id", "ts"], "vehicle_id"),
    "fact_vehicle_status": (["vehicle_id", "ts"], "vehicle_id"),
    "fact_vehicle_observation": (
        ["vehicle_id", "window_end", "i24_segment_id", "lane"],
        "vehicle_id",
    ),
    "fact_inrix_estimate": (["corridor_id", "xd_code", "measured_at"], "corridor_id"),
    "fact_speed_planner": (["corridor_id", "plan_id", "lane", "i24_segment_id"], "corridor_id"),
    "plan_run": (["corridor_id", "plan_id"], "corridor_id"),
}
DIMENSION_KEYS = {
    "dim_corridor": ["corridor_id"],
    "dim_vehicle": ["vehicle_id"],
    "dim_inrix_segment": ["xd_code"],
    "dim_i24_segment": ["i24_segment_id"],
}
FOREIGN_KEYS = {
    ("fact_vehicle_ping", "vehicle_id", "dim_vehicle"),
    ("fact_vehicle_status", "vehicle_id", "dim_vehicle"),
    ("fact_vehicle_observation", "vehicle_id", "dim_vehicle"),
    ("fact_vehicle_observation", "i24_segment_id", "dim_i24_segment"),
    ("fact_inrix_estimate", "xd_code", "dim_inrix_segment"),
    ("fact_inrix_estimate", "corridor_id", "dim_corridor"),
    ("fact_speed_planner", "i24_segment_id", "dim_i24_segment"),
    ("fact_speed_planner", "plan_id", "plan_run"),
    ("dim_i24_segment", "xd_code", "dim_inrix_segment"),
    ("dim_vehicle", "corridor_id", "dim_corridor"),
}


@pytest.fixture
def empty_engine(engine: Engine) -> Engine:
    """A database taken down to base first (the fixture database starts at head)."""
    downgrade(engine, "base")
    return engine


def primary_key(engine: Engine, table: str) -> list[str]:
    with engine.connect() as connection:
        return list(
            connection.execute(
                text(
                    """
                    SELECT kcu.column_name
                    FROM information_schema.table_constraints tc
                    JOIN information_schema.key_column_usage kcu
                      ON kcu.constraint_name = tc.constraint_name
                     AND kcu.table_name = tc.table_name
                    WHERE tc.table_name = :table AND tc.constraint_type = 'PRIMARY KEY'
                    ORDER BY kcu.ordinal_position
                    """
                ),
                {"table": table},
            ).scalars()
        )


def test_upgrade_downgrade_upgrade_round_trip(empty_engine: Engine) -> None:
    with empty_engine.connect() as connection:
        tables = connection.execute(
            text(
                "SELECT count(*) FROM information_schema.tables WHERE table_schema = 'public' "
                "AND table_name <> 'alembic_version'"
            )
        ).scalar_one()
    assert tables == 0
    upgrade(empty_engine)
    downgrade(empty_engine, "base")
    upgrade(empty_engine)
    assert primary_key(empty_engine, "fact_vehicle_ping") == ["vehicle_id", "ts"]


def test_one_head_and_models_agree_with_migrations(engine: Engine) -> None:
    heads = ScriptDirectory.from_config(alembic_config()).get_heads()
    assert heads == [head_revision()]
    with engine.begin() as connection:
        config = alembic_config()
        config.attributes["connection"] = connection
        command.check(config)  # raises if autogenerate would emit any operation


@pytest.mark.parametrize(("table", "key"), sorted(FACT_KEYS.items()))
def test_fact_keys_include_their_distribution_column(
    engine: Engine, table: str, key: tuple[list[str], str]
) -> None:
    columns, distribution = key
    assert primary_key(engine, table) == columns
    assert distribution in columns


@pytest.mark.parametrize(("table", "key"), sorted(DIMENSION_KEYS.items()))
def test_dimension_keys(engine: Engine, table: str, key: list[str]) -> None:
    assert primary_key(engine, table) == key


def test_foreign_keys_from_facts_to_dimensions(engine: Engine) -> None:
    with engine.connect() as connection:
        rows = connection.execute(
            text(
                """
                SELECT DISTINCT kcu.table_name, kcu.column_name, ccu.table_name
                FROM information_schema.table_constraints tc
                JOIN information_schema.key_column_usage kcu
                  ON kcu.constraint_name = tc.constraint_name
                JOIN information_schema.constraint_column_usage ccu
                  ON ccu.constraint_name = tc.constraint_name
                WHERE tc.constraint_type = 'FOREIGN KEY'
                """
            )
        ).all()
    found = {tuple(row) for row in rows}
    assert FOREIGN_KEYS <= found, FOREIGN_KEYS - found


def test_every_fact_table_states_its_grain(engine: Engine) -> None:
    with engine.connect() as connection:
        rows = connection.execute(
            text(
                "SELECT relname, obj_description(oid, 'pg_class') FROM pg_class "
                "WHERE relname = ANY(:tables)"
            ),
            {"tables": list(FACT_KEYS)},
        ).all()
    comments = {row[0]: row[1] for row in rows}
    for table in FACT_KEYS:
        assert comments[table], f"{table} has no grain comment"
        assert comments[table].startswith("One row per"), comments[table]


def test_ping_table_is_partitioned_by_day(engine: Engine) -> None:
    with engine.connect() as connection:
        strategy = connection.execute(
            text("SELECT pg_get_partkeydef('fact_vehicle_ping'::regclass)")
        ).scalar_one()
        partitions = connection.execute(
            text("SELECT count(*) FROM pg_inherits WHERE inhparent = 'fact_vehicle_ping'::regclass")
        ).scalar_one()
    assert strategy == "RANGE (ts)"
    assert partitions >= 9  # yesterday .. a week ahead, plus the default partition


def test_a_target_that_names_no_revision_is_refused_before_the_database_is_touched() -> None:
    for target in ("head", "base", "0003", "-1", "+2"):
        check_revision(target)
    with pytest.raises(UnknownRevision, match="no migration revision 'nosuch'"):
        check_revision("nosuch")
    with pytest.raises(UnknownRevision, match="Multiple revisions start with '00'"):
        check_revision("00")
