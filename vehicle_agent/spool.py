"""Store-and-forward for pings: every ping is written to SQLite on disk first, and leaves the
spool only once the server has answered that it committed it (or rejected it for good).

A crash loses nothing that was written (WAL journal, synchronous=FULL: every ping is on the disk,
through a power cut, before `add` returns); a ping sent but not yet
deleted when the agent dies is sent again after restart and the server counts it as a duplicate
(its (vehicle_id, ts) key is unique), so every ping reaches the database exactly once. The spool
is bounded: past `max_rows` the oldest pings are dropped (and counted), so a car offline for
days cannot fill its disk.

A ping the disk cannot take (full, read-only, failing) is held in memory and written first by
the next `add` that can write: it counts in the backlog meanwhile, and once more than
`MAX_UNWRITTEN` wait the oldest are dropped and counted in `dropped`. Written nowhere, a full SD
card lost every ping of the drive with nothing counting them (an audit: 30 s engaged on a full
card, 30 pings gone and `spool_dropped` 0). Held pings are lost if the agent stops first,
logged and counted in `dropped` if the disk takes that much (`close`).

A file that cannot be opened at all (the card missing or read-only, a file where its folder
should be) is the same fault from the start: the spool holds its pings in memory, within the
same bound, and tries the file again at each `add`. It used to raise, and the agent refused to
start: a car must still drive on its stock ACC and hand back safely, and report the fault
(its backlog grows, as on a full card) rather than report nothing.

`power_safe=False` (synchronous=NORMAL) keeps what a crashed agent process wrote but not what a
power cut of the machine caught in flight; it is for simulated cars (sim.fleet), where a hundred
spools share one host disk: a flush per ping (~5.7 ms on this project's machine, against 0.07 ms
without) would block their control loop for most of its 0.1 s period (docs/performance.md).
"""

from __future__ import annotations

import json
import logging
import sqlite3
import threading
from collections import deque
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from vehicle_agent.logs import ThrottledLog

log = logging.getLogger(__name__)

SCHEMA = """
CREATE TABLE IF NOT EXISTS ping (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    body TEXT NOT NULL
);
CREATE TABLE IF NOT EXISTS counter (
    name TEXT PRIMARY KEY,
    value INTEGER NOT NULL
);
"""

# Pings held in memory while the disk takes none: an hour at 1 Hz (about 1 MB).
MAX_UNWRITTEN = 3_600


class PingSpool:
    """A bounded FIFO of pings in one SQLite file, shared by the agent's threads."""

    def __init__(self, path: Path, max_rows: int = 100_000, *, power_safe: bool = True) -> None:
        if max_rows < 1:
            raise ValueError("max_rows must be at least 1")
        self.path = path
        self.max_rows = max_rows
        self.power_safe = power_safe
        self._lock = threading.Lock()
        self._drop_log = ThrottledLog(log, interval_s=60.0)
        self._write_log = ThrottledLog(log, interval_s=60.0)
        self._unwritten: deque[str] = deque()
        self._unwritten_dropped = 0  # dropped from memory, counted on disk at the next write
        # None while the file cannot be opened (`_open`), which each write tries again.
        self._db: sqlite3.Connection | None = None
        # Kept in memory: count(*) reads the whole table, ~11 ms at 100,000 pings on x86, and
        # every add (1 Hz) and status report needs it; the write itself takes ~0.3 ms.
        self._backlog = 0
        self._open()

    def _open(self) -> sqlite3.Connection | None:
        """The file, opened (its folder made) unless it is open already; None, said in the
        log (once a minute at most), when the card cannot hold it."""
        if self._db is not None:
            return self._db
        db: sqlite3.Connection | None = None
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            db = sqlite3.connect(self.path, check_same_thread=False, isolation_level=None)
            db.execute("PRAGMA journal_mode=WAL")
            db.execute(f"PRAGMA synchronous={'FULL' if self.power_safe else 'NORMAL'}")
            db.executescript(SCHEMA)
            (backlog,) = db.execute("SELECT count(*) FROM ping").fetchone()
        except (OSError, sqlite3.Error) as error:
            if db is not None:
                db.close()
            self._write_log.warning(
                type(error).__name__,
                f"ping spool {self.path} cannot be opened ({error}): pings held in memory "
                f"(at most {MAX_UNWRITTEN}, then the oldest are dropped and counted) until it "
                "can",
            )
            return None
        self._db = db
        self._backlog = int(backlog)
        return db

    def close(self) -> None:
        """Write what is held in memory if the disk takes it now, say what it did not take
        (those pings end with the agent) and count it in `dropped` if the disk takes that,
        and close the file."""
        with self._lock:
            if self._unwritten and not self._write_held():
                lost = len(self._unwritten)
                uncounted = lost + self._unwritten_dropped
                if self._count_dropped(uncounted):
                    log.warning(
                        "ping spool closed with %d pings the disk did not take: lost, counted "
                        "in spool_dropped",
                        lost,
                    )
                else:
                    log.warning(
                        "ping spool closed with %d pings the disk did not take: lost, and not "
                        "counted: spool_dropped misses %d (the disk took not even their count)",
                        lost,
                        uncounted,
                    )
            if self._db is not None:
                self._db.close()

    def _count_dropped(self, amount: int) -> bool:
        """Add `amount` to the file's `dropped` in a transaction of its own; False when the
        disk does not take it or there is no file. A counter is a few bytes, which a card too
        full for the pings (a megabyte for an hour of them) may still take; uncounted, the
        pings held in memory at the stop vanished from the status reports' `spool_dropped`,
        a total since the file was made, which then went back after the next start."""
        db = self._db
        if db is None:
            return False
        try:
            with self._transaction(db):
                self._bump(db, "dropped", amount)
        except sqlite3.DatabaseError:
            return False
        return True

    def add(self, ping: Mapping[str, Any]) -> None:
        """Append a ping (committed to disk before returning, or held in memory while the disk
        takes none); drop the oldest past the bounds."""
        body = json.dumps(ping, separators=(",", ":"))
        with self._lock:
            self._unwritten.append(body)
            if len(self._unwritten) > MAX_UNWRITTEN:
                self._unwritten.popleft()
                self._unwritten_dropped += 1
            self._write_held()

    def _write_held(self) -> bool:
        """Write the pings held in memory (the newest last) in one transaction; False, and
        still held, when the disk takes none or the file cannot be opened. The caller holds
        the lock."""
        db = self._open()
        if db is None:
            return False
        try:
            with self._transaction(db):
                db.executemany(
                    "INSERT INTO ping (body) VALUES (?)", [(b,) for b in self._unwritten]
                )
                backlog = self._backlog + len(self._unwritten)
                excess = backlog - self.max_rows
                if excess > 0:
                    backlog -= db.execute(
                        "DELETE FROM ping WHERE id IN (SELECT id FROM ping ORDER BY id LIMIT ?)",
                        (excess,),
                    ).rowcount
                    self._bump(db, "dropped", excess)
                    self._drop_log.warning(
                        "dropped",
                        f"ping spool full ({self.max_rows} pings): the oldest dropped unsent "
                        "(counted in the status report's spool_dropped)",
                    )
                if self._unwritten_dropped:
                    self._bump(db, "dropped", self._unwritten_dropped)
        except sqlite3.DatabaseError as error:
            self._write_log.warning(
                type(error).__name__,
                f"ping spool cannot write ({error}): {len(self._unwritten)} pings held in "
                f"memory (at most {MAX_UNWRITTEN}, then the oldest are dropped and counted)",
            )
            return False
        self._unwritten.clear()
        self._unwritten_dropped = 0
        self._backlog = backlog
        return True

    @staticmethod
    @contextmanager
    def _transaction(db: sqlite3.Connection) -> Iterator[None]:
        """One write transaction, committed on success and rolled back on error.

        SQLite itself rolls back on some errors (a full disk); a ROLLBACK then fails with "no
        transaction is active", which would replace the error that says what went wrong.
        """
        db.execute("BEGIN IMMEDIATE")
        try:
            yield
            db.execute("COMMIT")
        except BaseException:
            if db.in_transaction:
                db.execute("ROLLBACK")
            raise

    @staticmethod
    def _bump(db: sqlite3.Connection, name: str, amount: int) -> None:
        db.execute(
            "INSERT INTO counter (name, value) VALUES (?, ?) "
            "ON CONFLICT (name) DO UPDATE SET value = value + excluded.value",
            (name, amount),
        )

    def oldest(self, limit: int) -> list[tuple[int, dict[str, Any]]]:
        """Up to `limit` pings on disk, oldest first, with their spool ids (pings held in
        memory are sent once written)."""
        with self._lock:
            if self._db is None:
                return []
            rows = self._db.execute(
                "SELECT id, body FROM ping ORDER BY id LIMIT ?", (limit,)
            ).fetchall()
        return [(int(row[0]), json.loads(row[1])) for row in rows]

    def newest(self) -> tuple[int, dict[str, Any]] | None:
        """The last ping spooled on disk, with its spool id (None: none is)."""
        with self._lock:
            if self._db is None:
                return None
            row = self._db.execute("SELECT id, body FROM ping ORDER BY id DESC LIMIT 1").fetchone()
        return None if row is None else (int(row[0]), json.loads(row[1]))

    def remove(self, ids: Sequence[int], rejected: int = 0) -> None:
        """Forget pings the server has answered for (ids `oldest` or `newest` gave, so the
        file is open)."""
        if not ids:
            return
        with self._lock:
            db = self._db
            assert db is not None, "spool ids come only from an open file"
            with self._transaction(db):
                # Ids the bound already dropped delete nothing, and are not counted.
                removed = db.executemany(
                    "DELETE FROM ping WHERE id = ?", [(i,) for i in ids]
                ).rowcount
                if rejected:
                    self._bump(db, "rejected", rejected)
            self._backlog -= removed

    def backlog(self) -> int:
        """Pings waiting for upload, on disk or held in memory."""
        with self._lock:
            return int(self._backlog) + len(self._unwritten)

    def counter(self, name: str) -> int:
        """A running total: `dropped` (past a bound) or `rejected` (by the server)."""
        with self._lock:
            row = (
                None
                if self._db is None
                else self._db.execute(
                    "SELECT value FROM counter WHERE name = ?", (name,)
                ).fetchone()
            )
            held = self._unwritten_dropped if name == "dropped" else 0
        return (int(row[0]) if row else 0) + held
