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
card, 30 pings gone and `spool_dropped` 0). Held pings are lost if the agent stops first.

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
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self.max_rows = max_rows
        self._lock = threading.Lock()
        self._drop_log = ThrottledLog(log, interval_s=60.0)
        self._write_log = ThrottledLog(log, interval_s=60.0)
        self._unwritten: deque[str] = deque()
        self._unwritten_dropped = 0  # dropped from memory, counted on disk at the next write
        self._db = sqlite3.connect(path, check_same_thread=False, isolation_level=None)
        self._db.execute("PRAGMA journal_mode=WAL")
        self._db.execute(f"PRAGMA synchronous={'FULL' if power_safe else 'NORMAL'}")
        self._db.executescript(SCHEMA)
        # Kept in memory: count(*) reads the whole table, ~11 ms at 100,000 pings on x86, and
        # every add (1 Hz) and status report needs it; the write itself takes ~0.3 ms.
        (self._backlog,) = self._db.execute("SELECT count(*) FROM ping").fetchone()

    def close(self) -> None:
        """Write what is held in memory if the disk takes it now, say what it did not take
        (those pings end with the agent), and close the file."""
        with self._lock:
            if self._unwritten and not self._write_held():
                log.warning(
                    "ping spool closed with %d pings the disk did not take: lost",
                    len(self._unwritten),
                )
            self._db.close()

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
        still held, when the disk takes none. The caller holds the lock."""
        try:
            with self._transaction():
                self._db.executemany(
                    "INSERT INTO ping (body) VALUES (?)", [(b,) for b in self._unwritten]
                )
                backlog = self._backlog + len(self._unwritten)
                excess = backlog - self.max_rows
                if excess > 0:
                    backlog -= self._db.execute(
                        "DELETE FROM ping WHERE id IN (SELECT id FROM ping ORDER BY id LIMIT ?)",
                        (excess,),
                    ).rowcount
                    self._bump("dropped", excess)
                    self._drop_log.warning(
                        "dropped",
                        f"ping spool full ({self.max_rows} pings): the oldest dropped unsent "
                        "(counted in the status report's spool_dropped)",
                    )
                if self._unwritten_dropped:
                    self._bump("dropped", self._unwritten_dropped)
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

    @contextmanager
    def _transaction(self) -> Iterator[None]:
        """One write transaction, committed on success and rolled back on error.

        SQLite itself rolls back on some errors (a full disk); a ROLLBACK then fails with "no
        transaction is active", which would replace the error that says what went wrong.
        """
        self._db.execute("BEGIN IMMEDIATE")
        try:
            yield
            self._db.execute("COMMIT")
        except BaseException:
            if self._db.in_transaction:
                self._db.execute("ROLLBACK")
            raise

    def _bump(self, name: str, amount: int) -> None:
        self._db.execute(
            "INSERT INTO counter (name, value) VALUES (?, ?) "
            "ON CONFLICT (name) DO UPDATE SET value = value + excluded.value",
            (name, amount),
        )

    def oldest(self, limit: int) -> list[tuple[int, dict[str, Any]]]:
        """Up to `limit` pings, oldest first, with their spool ids."""
        with self._lock:
            rows = self._db.execute(
                "SELECT id, body FROM ping ORDER BY id LIMIT ?", (limit,)
            ).fetchall()
        return [(int(row[0]), json.loads(row[1])) for row in rows]

    def newest(self) -> tuple[int, dict[str, Any]] | None:
        """The last ping spooled, with its spool id (None: the spool is empty)."""
        with self._lock:
            row = self._db.execute("SELECT id, body FROM ping ORDER BY id DESC LIMIT 1").fetchone()
        return None if row is None else (int(row[0]), json.loads(row[1]))

    def remove(self, ids: Sequence[int], rejected: int = 0) -> None:
        """Forget pings the server has answered for."""
        if not ids:
            return
        with self._lock:
            with self._transaction():
                # Ids the bound already dropped delete nothing, and are not counted.
                removed = self._db.executemany(
                    "DELETE FROM ping WHERE id = ?", [(i,) for i in ids]
                ).rowcount
                if rejected:
                    self._bump("rejected", rejected)
            self._backlog -= removed

    def backlog(self) -> int:
        """Pings waiting for upload, on disk or held in memory."""
        with self._lock:
            return int(self._backlog) + len(self._unwritten)

    def counter(self, name: str) -> int:
        """A running total: `dropped` (past a bound) or `rejected` (by the server)."""
        with self._lock:
            row = self._db.execute("SELECT value FROM counter WHERE name = ?", (name,)).fetchone()
            held = self._unwritten_dropped if name == "dropped" else 0
        return (int(row[0]) if row else 0) + held
