"""The ping spool: oldest first, bounded, and nothing written is lost when the agent dies."""

from __future__ import annotations

import logging
import sqlite3
from pathlib import Path

import pytest

from vehicle_agent.spool import PingSpool


def spool_messages(caplog: pytest.LogCaptureFixture) -> list[str]:
    """The spool's own log lines: another test's button deadman timer (a thread) may log into
    the same capture while this one runs."""
    return [record.message for record in caplog.records if record.name == "vehicle_agent.spool"]


def test_pings_leave_oldest_first_and_only_when_removed(tmp_path: Path) -> None:
    spool = PingSpool(tmp_path / "spool.sqlite")
    for second in range(5):
        spool.add({"ts": f"2024-01-01T00:00:0{second}Z"})
    rows = spool.oldest(3)
    assert [ping["ts"][-3:-1] for _, ping in rows] == ["00", "01", "02"]
    spool.remove([row_id for row_id, _ in rows], rejected=1)
    assert spool.backlog() == 2
    assert spool.counter("rejected") == 1


def test_the_spool_is_bounded_and_counts_what_it_dropped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    spool = PingSpool(tmp_path / "spool.sqlite", max_rows=3)
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        for index in range(5):
            spool.add({"n": index})
    assert [ping["n"] for _, ping in spool.oldest(10)] == [2, 3, 4]
    assert spool.counter("dropped") == 2
    # said in the car's log (once a minute at most), not only counted in the file
    assert spool_messages(caplog) == [
        "ping spool full (3 pings): the oldest dropped unsent (counted in the status report's "
        "spool_dropped)"
    ]
    with pytest.raises(ValueError, match="max_rows"):
        PingSpool(tmp_path / "other.sqlite", max_rows=0)


@pytest.mark.parametrize(("power_safe", "synchronous"), [(True, 2), (False, 1)])
def test_a_crashed_agent_loses_nothing_written(
    tmp_path: Path, power_safe: bool, synchronous: int
) -> None:
    path = tmp_path / "spool.sqlite"
    crashed = PingSpool(path, power_safe=power_safe)
    # FULL (2): on disk through a power cut; NORMAL (1): through the process dying only.
    assert crashed._db.execute("PRAGMA synchronous").fetchone()[0] == synchronous
    for index in range(3):
        crashed.add({"n": index})
    # Never closed: a second process opens the same file as the restarted agent would.
    restarted = PingSpool(path)
    assert [ping["n"] for _, ping in restarted.oldest(10)] == [0, 1, 2]
    restarted.add({"n": 3})
    assert restarted.backlog() == 4


def test_the_backlog_matches_the_file_through_drops_removals_and_a_restart(
    tmp_path: Path,
) -> None:
    path = tmp_path / "spool.sqlite"
    spool = PingSpool(path, max_rows=4)

    def on_disk() -> int:
        return int(spool._db.execute("SELECT count(*) FROM ping").fetchone()[0])

    for index in range(6):
        spool.add({"n": index})
    sent = [row_id for row_id, _ in spool.oldest(3)]
    spool.add({"n": 6})  # drops the oldest, which is also the first of the batch in flight
    assert spool.backlog() == on_disk() == 4
    spool.remove(sent)  # its id is gone already: two pings leave, not three
    assert spool.backlog() == on_disk() == 2
    assert [ping["n"] for _, ping in spool.oldest(10)] == [5, 6]
    # Restarted with a smaller bound: the count comes from the file, the bound holds at once.
    smaller = PingSpool(path, max_rows=1)
    assert smaller.backlog() == 2
    smaller.add({"n": 7})
    assert smaller.backlog() == 1
    assert [ping["n"] for _, ping in smaller.oldest(10)] == [7]
    assert smaller.counter("dropped") == 5


def full_disk(spool: PingSpool) -> sqlite3.Connection:
    """The spool's file limited to what it holds, as SQLite sees a full SD card."""
    connection = spool._db
    (pages,) = connection.execute("PRAGMA page_count").fetchone()
    connection.execute(f"PRAGMA max_page_count = {pages}")
    return connection


def test_pings_a_full_disk_cannot_take_are_held_and_written_in_order_after(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """On a full disk every ping was lost, and nothing counted them: 30 s engaged on a full
    card left 30 holes in the drive and `spool_dropped` at 0. They wait in memory, count in the
    backlog, and are written first, in order, once the disk takes them. (SQLite rolls a
    transaction back itself when the disk is full; the spool's own ROLLBACK must not then fail
    with "no transaction is active".)"""
    spool = PingSpool(tmp_path / "spool.sqlite")
    spool.add({"n": "before"})
    connection = full_disk(spool)
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        for index in range(30):
            spool.add({"n": index, "pad": "x" * 500})
    assert spool.backlog() == 31
    assert spool.counter("dropped") == 0
    assert spool_messages(caplog) == [
        "ping spool cannot write (database or disk is full): 1 pings held in memory (at most "
        "3600, then the oldest are dropped and counted)"
    ]
    connection.execute("PRAGMA max_page_count = 1000000")  # space freed
    spool.add({"n": "after"})
    assert spool.backlog() == 32
    assert [ping["n"] for _, ping in spool.oldest(100)] == ["before", *range(30), "after"]


def test_past_the_memory_bound_the_oldest_held_pings_are_dropped_and_counted(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr("vehicle_agent.spool.MAX_UNWRITTEN", 5)
    spool = PingSpool(tmp_path / "spool.sqlite")
    connection = full_disk(spool)
    for index in range(8):
        spool.add({"n": index, "pad": "x" * 5000})
    assert (spool.backlog(), spool.counter("dropped")) == (5, 3)
    connection.execute("PRAGMA max_page_count = 1000000")
    spool.add({"n": 8})
    assert [ping["n"] for _, ping in spool.oldest(100)] == [4, 5, 6, 7, 8]
    assert (spool.backlog(), spool.counter("dropped")) == (5, 4)
    reopened = PingSpool(tmp_path / "spool.sqlite")  # the count was written with them
    assert reopened.counter("dropped") == 4


def test_closing_writes_what_is_held_if_it_can_and_says_what_it_could_not(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    """Held pings vanished at shutdown with no line and no count."""
    spool = PingSpool(tmp_path / "spool.sqlite")
    connection = full_disk(spool)
    for index in range(3):
        spool.add({"n": index, "pad": "x" * 5000})
    connection.execute("PRAGMA max_page_count = 1000000")  # space freed before the stop
    spool.close()
    assert [ping["n"] for _, ping in PingSpool(tmp_path / "spool.sqlite").oldest(10)] == [0, 1, 2]

    full = PingSpool(tmp_path / "full.sqlite")
    full_disk(full)
    for index in range(3):
        full.add({"n": index, "pad": "x" * 5000})
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        full.close()
    assert "ping spool closed with 3 pings the disk did not take: lost" in caplog.text


def test_a_spool_whose_file_cannot_be_opened_holds_its_pings_in_memory_until_it_can(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A missing or read-only SD card raised here, and the agent refused to start: a car must
    still drive and hand back. Its pings wait in memory, within a full card's bound, count in
    the backlog (and past the bound in `dropped`), and are written once the file opens."""
    monkeypatch.setattr("vehicle_agent.spool.MAX_UNWRITTEN", 5)
    card = tmp_path / "card"
    card.write_text("")  # a file where the spool's folder should be: it cannot be made
    path = card / "spool.sqlite"
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        spool = PingSpool(path)
        for index in range(8):
            spool.add({"n": index})
    assert (spool.backlog(), spool.counter("dropped")) == (5, 3)
    assert (spool.oldest(10), spool.newest()) == ([], None)  # nothing on disk to send
    (message,) = spool_messages(caplog)  # once a minute at most, not once a ping
    assert message.startswith(f"ping spool {path} cannot be opened ([Errno 17] File exists")
    assert message.endswith(
        "pings held in memory (at most 5, then the oldest are dropped and counted) until it can"
    )
    card.unlink()  # the card is back
    spool.add({"n": 8})
    assert [ping["n"] for _, ping in spool.oldest(10)] == [4, 5, 6, 7, 8]
    assert (spool.backlog(), spool.counter("dropped")) == (5, 4)
    spool.close()
    assert PingSpool(path).counter("dropped") == 4


def test_pings_lost_at_close_are_counted_in_spool_dropped_when_the_disk_takes_the_count(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Held pings the disk did not take at the stop were logged but counted nowhere: the
    status reports after the next start said nothing of them, and `spool_dropped`, a total
    since the file was made, went back by the pings the memory's bound had dropped. A card too
    full for the pings may still take their count, a few bytes."""
    monkeypatch.setattr("vehicle_agent.spool.MAX_UNWRITTEN", 3)
    full = PingSpool(tmp_path / "full.sqlite")
    full_disk(full)
    for index in range(5):
        full.add({"n": index, "pad": "x" * 5000})
    assert (full.backlog(), full.counter("dropped")) == (3, 2)
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        full.close()
    assert spool_messages(caplog)[-1] == (
        "ping spool closed with 3 pings the disk did not take: lost, counted in spool_dropped"
    )
    restarted = PingSpool(tmp_path / "full.sqlite")
    assert (restarted.backlog(), restarted.counter("dropped")) == (0, 5)

    (tmp_path / "card").write_text("")  # no file at all: not even the count can be kept
    missing = PingSpool(tmp_path / "card" / "spool.sqlite")
    for index in range(5):
        missing.add({"n": index})
    with caplog.at_level(logging.WARNING, logger="vehicle_agent.spool"):
        missing.close()
    assert spool_messages(caplog)[-1] == (
        "ping spool closed with 3 pings the disk did not take: lost, and not counted: "
        "spool_dropped misses 5 (the disk took not even their count)"
    )
