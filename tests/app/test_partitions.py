"""Ping partitions exist ahead of time; rows never fail for want of one; retention drops days."""

from __future__ import annotations

import threading
from datetime import UTC, date, datetime, time, timedelta

import pytest
from sqlalchemy import Engine, text
from sqlalchemy.exc import IntegrityError

from app.maintenance import maintain
from tests.support.databases import sessions_waiting_on_a_lock

INSERT_PING = text(
    "INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps) "
    "VALUES ('SF-001', :ts, 36.0, -86.6, 25.0)"
)


def partition_of(engine: Engine, ts: datetime) -> str:
    with engine.connect() as connection:
        return str(
            connection.execute(
                text(
                    "SELECT tableoid::regclass::text FROM fact_vehicle_ping "
                    "WHERE vehicle_id = 'SF-001' AND ts = :ts"
                ),
                {"ts": ts},
            ).scalar_one()
        )


def noon(day: date) -> datetime:
    return datetime.combine(day, time(12), tzinfo=UTC)


def test_pings_for_tomorrow_and_the_day_after_insert_without_a_manual_step(
    seeded_engine: Engine,
) -> None:
    today = datetime.now(UTC).date()
    for ahead in (1, 2):
        ts = noon(today + timedelta(days=ahead))
        with seeded_engine.begin() as connection:
            connection.execute(INSERT_PING, {"ts": ts})
        day = (today + timedelta(days=ahead)).strftime("%Y%m%d")
        assert partition_of(seeded_engine, ts) == f"fact_vehicle_ping_p{day}"


def test_a_ping_beyond_the_partitions_is_kept_and_later_moved_to_its_day(
    seeded_engine: Engine,
) -> None:
    far = datetime.now(UTC).date() + timedelta(days=40)
    ts = noon(far)
    with seeded_engine.begin() as connection:
        connection.execute(INSERT_PING, {"ts": ts})
    assert partition_of(seeded_engine, ts) == "fact_vehicle_ping_default"
    with seeded_engine.begin() as connection:
        result = maintain(connection, ahead_days=45, retention_days=90)
    assert result.partitions_created >= 30
    assert partition_of(seeded_engine, ts) == f"fact_vehicle_ping_p{far:%Y%m%d}"


def test_retention_drops_whole_days_past_the_window(seeded_engine: Engine) -> None:
    old_day = datetime.now(UTC).date() - timedelta(days=10)
    with seeded_engine.begin() as connection:
        connection.execute(
            text("SELECT ensure_ping_partitions(CAST(:day AS date), CAST(:day AS date))"),
            {"day": old_day},
        )
        connection.execute(INSERT_PING, {"ts": noon(old_day)})
        connection.execute(INSERT_PING, {"ts": noon(datetime.now(UTC).date())})
    with seeded_engine.begin() as connection:
        result = maintain(connection, ahead_days=7, retention_days=5)
    assert result.partitions_dropped == 1
    with seeded_engine.connect() as connection:
        remaining = connection.execute(text("SELECT count(*) FROM fact_vehicle_ping")).scalar_one()
    assert remaining == 1


def test_a_duplicate_vehicle_and_ts_is_refused_by_the_database(seeded_engine: Engine) -> None:
    ts = noon(datetime.now(UTC).date())
    with seeded_engine.begin() as connection:
        connection.execute(INSERT_PING, {"ts": ts})
    with (
        pytest.raises(IntegrityError, match="duplicate key value violates unique constraint"),
        seeded_engine.begin() as c,
    ):
        c.execute(INSERT_PING, {"ts": ts})


def test_retention_reaches_old_pings_without_a_partition_and_old_status_reports(
    seeded_engine: Engine,
) -> None:
    """Partitions are made from yesterday on: a ping of ten days ago (a spool uploaded after a
    week offline) waits in the default partition, and retention must reach it there. Status
    reports, one every ~10 s from every car, age out with the pings."""
    old_ts = noon(datetime.now(UTC).date() - timedelta(days=10))
    recent_ts = noon(datetime.now(UTC).date() - timedelta(days=3))
    with seeded_engine.begin() as connection:
        for ts in (old_ts, recent_ts):
            connection.execute(INSERT_PING, {"ts": ts})
            connection.execute(
                text("INSERT INTO fact_vehicle_status (vehicle_id, ts) VALUES ('SF-001', :ts)"),
                {"ts": ts},
            )
    assert partition_of(seeded_engine, old_ts) == "fact_vehicle_ping_default"
    with seeded_engine.begin() as connection:
        result = maintain(connection, ahead_days=7, retention_days=5)
    assert (result.default_rows_deleted, result.status_reports_deleted) == (1, 1)
    with seeded_engine.connect() as connection:
        for table in ("fact_vehicle_ping", "fact_vehicle_status"):
            kept = connection.execute(text(f"SELECT ts FROM {table}")).scalars().all()
            assert kept == [recent_ts], table


def a_zone_off_the_utc_date() -> str:
    """A time zone whose date is not the UTC date now: UTC+14 from 10:00 UTC, UTC-12 before
    12:00 UTC."""
    return "Pacific/Kiritimati" if datetime.now(UTC).hour >= 12 else "Etc/GMT+12"


def test_retention_counts_utc_days_whatever_the_sessions_time_zone(seeded_engine: Engine) -> None:
    """Partitions are UTC days; a session in another zone (libpq's PGTZ overrides the engine's
    `timezone=UTC`) read `current_date` there, and dropped or deleted a day early or late."""
    today = datetime.now(UTC).date()
    first_kept = today - timedelta(days=3)
    kept_ts = datetime.combine(first_kept, time(0, 0, 30), tzinfo=UTC)
    gone_ts = kept_ts - timedelta(minutes=1)
    with seeded_engine.begin() as connection:
        connection.execute(
            text("SELECT ensure_ping_partitions(CAST(:first AS date), CAST(:last AS date))"),
            {"first": today - timedelta(days=6), "last": today},
        )
        for ts in (gone_ts, kept_ts):
            connection.execute(
                text("INSERT INTO fact_vehicle_status (vehicle_id, ts) VALUES ('SF-001', :ts)"),
                {"ts": ts},
            )
    with seeded_engine.begin() as connection:
        connection.execute(
            text("SELECT set_config('TimeZone', :zone, true)"), {"zone": a_zone_off_the_utc_date()}
        )
        maintain(connection, ahead_days=2, retention_days=3)
    with seeded_engine.connect() as connection:
        days = connection.execute(
            text(
                "SELECT min(to_date(right(child.relname, 8), 'YYYYMMDD')) FROM pg_inherits "
                "JOIN pg_class child ON child.oid = pg_inherits.inhrelid "
                "WHERE pg_inherits.inhparent = 'fact_vehicle_ping'::regclass "
                "AND child.relname <> 'fact_vehicle_ping_default'"
            )
        ).scalar_one()
        kept = connection.execute(text("SELECT ts FROM fact_vehicle_status")).scalars().all()
    assert days == first_kept
    assert kept == [kept_ts]


def test_two_passes_at_once_make_each_partition_once_and_both_succeed(
    seeded_engine: Engine,
) -> None:
    """Every worker and replica runs the pass; two reaching new days together both created
    the same partitions, and the later failed whole (a unique violation in PostgreSQL's
    catalog), its retention rolled back with it. The passes now run one at a time."""
    outcome: list[object] = []

    def second_pass() -> None:
        try:
            with seeded_engine.begin() as connection:
                outcome.append(maintain(connection, ahead_days=60, retention_days=90))
        except Exception as error:  # the failure is the finding
            outcome.append(error)

    with seeded_engine.connect() as first:
        transaction = first.begin()
        created = maintain(first, ahead_days=60, retention_days=90).partitions_created
        assert created > 40
        racing = threading.Thread(target=second_pass)
        racing.start()
        waiting = sessions_waiting_on_a_lock(seeded_engine)
        assert waiting == 1
        transaction.commit()
        racing.join(timeout=30)
    assert len(outcome) == 1
    assert not isinstance(outcome[0], Exception), outcome[0]
    assert outcome[0].partitions_created == 0


def test_the_pass_forgets_failed_logins_of_addresses_quiet_for_a_day(seeded_engine: Engine) -> None:
    """A guesser rotating addresses adds a row an attempt; an address that has not failed for
    a day has long stopped waiting (5 min at most), and its row goes."""
    with seeded_engine.begin() as connection:
        connection.execute(
            text(
                "INSERT INTO ops_user (username, password_hash, role) "
                "VALUES ('admin', 'scrypt$x', 'admin')"
            )
        )
        connection.execute(
            text(
                "INSERT INTO ops_login_failure VALUES "
                "('admin', '203.0.113.1', 9, now() - interval '25 hours'), "
                "('admin', '203.0.113.2', 3, now() - interval '23 hours')"
            )
        )
        result = maintain(connection, ahead_days=7, retention_days=90)
        left = connection.execute(text("SELECT client_address FROM ops_login_failure")).scalars()
        assert list(left) == ["203.0.113.2"]
    assert result.login_failures_deleted == 1
