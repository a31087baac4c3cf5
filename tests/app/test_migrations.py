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


# --- 0012: the vehicle assignment history ------------------------------------------------------

EDIE_FIELD = "analytics.edie_field(timestamptz, timestamptz, double precision, double precision)"


DEFINITIONS = {
    "plan_adherence": "pg_get_viewdef('analytics.plan_adherence'::regclass)",
    "edie_field": "pg_get_functiondef(CAST(:edie AS regprocedure))",
    "edie_boxes": "pg_get_viewdef('analytics.edie_boxes'::regclass)",
    "comments": "concat_ws(' | ', obj_description('analytics.plan_adherence'::regclass),"
    " obj_description('analytics.edie_boxes'::regclass),"
    " obj_description(CAST(:edie AS regprocedure)))",
    "table": "to_regclass('dim_vehicle_assignment')::text",
    "trigger function": "to_regprocedure('record_vehicle_assignment()')::text",
}


def definitions(engine: Engine) -> dict[str, str | None]:
    """The definitions 0012 replaces, and whether its table and trigger function exist."""
    with engine.connect() as connection:
        return {
            name: connection.execute(text(f"SELECT {sql}"), {"edie": EDIE_FIELD}).scalar_one()
            for name, sql in DEFINITIONS.items()
        }


def test_the_assignment_history_downgrades_to_the_previous_definitions(
    empty_engine: Engine,
) -> None:
    upgrade(empty_engine, "0011")
    at_0011 = definitions(empty_engine)
    upgrade(empty_engine, "0012")
    at_0012 = definitions(empty_engine)
    downgrade(empty_engine, "0011")

    assert definitions(empty_engine) == at_0011
    assert (at_0011["table"], at_0011["trigger function"]) == (None, None)
    assert (at_0012["table"], at_0012["trigger function"]) == (
        "dim_vehicle_assignment",
        "record_vehicle_assignment()",
    )
    for name in ("plan_adherence", "edie_field"):
        assert "dim_vehicle_assignment" in str(at_0012[name])
        assert "dim_vehicle_assignment" not in str(at_0011[name])
    assert at_0012["comments"] == at_0011["comments"]
    upgrade(empty_engine)


def test_the_assignment_history_backfills_one_open_row_per_vehicle(seeded_engine: Engine) -> None:
    """Upgrading a database with a fleet: each car's current assignment, from the start of time
    (when it began is not known), so the views answer as before the upgrade."""
    downgrade(seeded_engine, "0011")
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE dim_vehicle SET assigned_lane = 4 WHERE vehicle_id = 'SF-001'")
        )
        connection.execute(
            text(
                "INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps, x_m) "
                "SELECT 'SF-001', date_trunc('hour', now()) - interval '1 hour' + s * interval "
                "'1 second', 36.0, -86.6, 20, 1010 + 20 * s FROM generate_series(0, 9) s"
            )
        )
    boxes = "SELECT * FROM analytics.edie_boxes ORDER BY corridor_id, t_start, x_start_m"
    with seeded_engine.connect() as connection:
        before = connection.execute(text(boxes)).all()
    upgrade(seeded_engine, "0012")

    with seeded_engine.connect() as connection:
        rows = connection.execute(
            text(
                "SELECT vehicle_id, valid_from::text, valid_to::text, corridor_id, route,"
                " assigned_lane FROM dim_vehicle_assignment ORDER BY vehicle_id"
            )
        ).all()
        vehicles = connection.execute(
            text("SELECT vehicle_id, corridor_id, route, assigned_lane FROM dim_vehicle ORDER BY 1")
        ).all()
    assert len(rows) == len(vehicles) == 100
    assert {(row[1], row[2]) for row in rows} == {("-infinity", "infinity")}
    assert [(row[0], *row[3:]) for row in rows] == [tuple(vehicle) for vehicle in vehicles]
    assert ("SF-001", "I-24-WB", "A", 4) in [tuple(vehicle) for vehicle in vehicles]
    with seeded_engine.connect() as connection:
        assert connection.execute(text(boxes)).all() == before != []
