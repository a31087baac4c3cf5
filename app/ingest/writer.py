"""Group commit for pings: many requests' rows in one INSERT, each answered after the commit.

Requests hand their validated rows to the process's PingWriter and wait. The writer takes
everything queued, writes it (app.ingest.sql: one autocommit statement for a small group, COPY
in one transaction for a large one), and only once it is committed tells each request how many
of its rows were inserted and how many were duplicates. Up to `concurrency` groups are in
flight at once: while one group is being written the next one collects, so under load a group
holds many requests and at low load a lone ping is written at once (no timer adds latency).

Duplicates are counted per request, also across requests of one group: the first occurrence of
a (vehicle_id, ts) in the group is the one sent to the database, later ones are duplicates at
once; a sent row the database did not insert (ON CONFLICT DO NOTHING) was already stored.
A duplicate saying something else than the ping kept (the first in the group, or the stored
one: app.ingest.sql.CONFLICTING, asked only when a group met stored rows) is a conflict: the
ping kept stays, and the request learns which of its duplicates conflicted.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np
import psycopg
from psycopg.pq import TransactionStatus
from sqlalchemy.ext.asyncio import AsyncConnection, AsyncEngine

from app.core import metrics
from app.ingest.pings import PingRow
from app.ingest.sql import (
    CONFLICTING,
    CONTENT_COLUMNS,
    COPY_INCOMING,
    COPY_STORED,
    COPY_TYPES,
    CREATE_INCOMING,
    INSERT_FROM_INCOMING,
    PING_COLUMNS,
    SMALL_GROUP_ROWS,
    insert_values,
)
from contract.corridor import trusted_heading
from contract.values import NEGLIGIBLE

log = logging.getLogger(__name__)

# Rows per statement: big enough to amortise the round trip, small enough that one group's
# parameters stay a few MB and a statement takes well under the statement timeout.
MAX_GROUP_ROWS = 20_000
_LANE = PingRow._fields.index("lane")  # x_m follows lane in the table
# Up to this many fixes of one corridor in a group are map-matched one by one in plain floats.
SCALAR_MATCH_FIXES = 16
# Positions of the REAL (float4) columns in a written row (the row number excluded).
_FLOAT4 = tuple(n for n, (_, pg_type) in enumerate(PING_COLUMNS) if pg_type == "float4")
# Positions in a PingRow of what the car said beside the key (app.ingest.sql.CONTENT_COLUMNS).
_CONTENT = tuple(PingRow._fields.index(name) for name, _ in CONTENT_COLUMNS)
# ... and in a written row (x_m follows lane), key first.
_WRITTEN_KEY_AND_CONTENT = tuple(
    n
    for n, column in enumerate(PING_COLUMNS)
    if column[0] in ("vehicle_id", "ts") or column in CONTENT_COLUMNS
)

PingKey = tuple[str, datetime]


class WriterStopped(RuntimeError):
    """The server is shutting down; the request's rows were not written."""


class RefusedByDatabase(RuntimeError):
    """The database refused a request's rows (a constraint); nothing of them was written."""


class UnstorableValue(RefusedByDatabase):
    """A value of the request's rows cannot be stored (e.g. a NUL in text); `field` names it."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


@dataclass(frozen=True, slots=True)
class WriteOutcome:
    """What happened to one request's rows; `conflicts` are the keys of those duplicates that
    differ from the ping kept at their (vehicle_id, ts)."""

    accepted: int
    duplicates: int
    conflicts: tuple[PingKey, ...] = ()


@dataclass(slots=True)
class _Submission:
    rows: Sequence[PingRow]
    answer: asyncio.Future[WriteOutcome]


class PingWriter:
    """The per-process writer of fact_vehicle_ping."""

    def __init__(
        self, engine: AsyncEngine, *, concurrency: int = 2, max_group_rows: int = MAX_GROUP_ROWS
    ) -> None:
        self._engine = engine
        self._max_group_rows = max_group_rows
        self._slots = asyncio.Semaphore(concurrency)
        self._queue: asyncio.Queue[_Submission] = asyncio.Queue()
        self._flushes: set[asyncio.Task[None]] = set()
        self._runner: asyncio.Task[None] | None = None
        # Connections kept between groups (one per slot at most): no pool checkout and no
        # pre-ping round trip per group. A connection that fails is dropped, not reused.
        self._idle: list[AsyncConnection] = []

    def start(self) -> None:
        """Start collecting groups (inside the running event loop)."""
        if self._runner is None:
            self._runner = asyncio.create_task(self._run(), name="ping-writer")

    async def stop(self) -> None:
        """Finish the groups in flight, then refuse what is still queued."""
        if self._runner is not None:
            self._runner.cancel()
            await asyncio.gather(self._runner, return_exceptions=True)
            self._runner = None
        await asyncio.gather(*self._flushes, return_exceptions=True)
        for connection in self._idle:
            # In autocommit mode: not fit for the engine's pool, whose users expect transactions.
            with contextlib.suppress(Exception):
                await connection.invalidate()
            await connection.close()
        self._idle.clear()
        while not self._queue.empty():
            submission = self._queue.get_nowait()
            if not submission.answer.done():
                submission.answer.set_exception(WriterStopped("server shutting down"))

    async def write(self, rows: Sequence[PingRow]) -> WriteOutcome:
        """Write the rows; returns once the transaction holding them has committed."""
        if not rows:
            return WriteOutcome(0, 0)
        if self._runner is None:
            raise WriterStopped("server shutting down")
        answer: asyncio.Future[WriteOutcome] = asyncio.get_running_loop().create_future()
        self._queue.put_nowait(_Submission(rows, answer))
        return await answer

    async def _connect(self) -> AsyncConnection:
        """A connection of the engine (its timeouts), switched to autocommit for the writer.

        Never returned to the engine's pool: the writer keeps it until it fails or stops.
        """
        connection = await self._engine.connect()
        try:
            pooled = await connection.get_raw_connection()
            driver = pooled.driver_connection
            assert isinstance(driver, psycopg.AsyncConnection)
            if driver.info.transaction_status != TransactionStatus.IDLE:
                await driver.rollback()  # the pool's pre-ping opened one
            await driver.set_autocommit(True)
        except BaseException:
            with contextlib.suppress(Exception):
                await connection.invalidate()
                await connection.close()
            raise
        return connection

    async def _run(self) -> None:
        while True:
            await self._slots.acquire()
            try:
                group = [await self._queue.get()]
            except asyncio.CancelledError:
                self._slots.release()
                raise
            size = len(group[0].rows)
            while size < self._max_group_rows and not self._queue.empty():
                submission = self._queue.get_nowait()
                group.append(submission)
                size += len(submission.rows)
            # A request that gave up waiting (its deadline passed: answered 503, not
            # acknowledged) is not written; its car resends.
            group = [submission for submission in group if not submission.answer.done()]
            if not group:
                self._slots.release()
                continue
            task = asyncio.create_task(self._flush(group))
            self._flushes.add(task)
            task.add_done_callback(self._flushes.discard)

    async def _flush(self, group: list[_Submission]) -> None:
        try:
            await self._answer(group)
        finally:
            self._slots.release()

    async def _answer(self, group: list[_Submission]) -> None:
        try:
            outcomes = await self._write_group(group)
        except (psycopg.DataError, psycopg.IntegrityError, UnicodeEncodeError) as error:
            # Rows the checks let through were refused (a value PostgreSQL cannot store, or a
            # vehicle just removed from the roster). The group is split in halves and each
            # half retried, so the other requests commit and only the request(s) holding
            # such rows fail: one request's bad row never costs another car its ping.
            if len(group) == 1:
                _fail(group, _refusal(error, group[0].rows))
                return
            log.info("group of %d requests refused; retrying it in halves", len(group))
            middle = len(group) // 2
            await self._answer(group[:middle])
            await self._answer(group[middle:])
            return
        except Exception as error:  # every waiting request gets it (outages become 503)
            _fail(group, error)
            return
        for submission, outcome in zip(group, outcomes, strict=True):
            if not submission.answer.done():
                submission.answer.set_result(outcome)

    async def _write_group(self, group: list[_Submission]) -> list[WriteOutcome]:
        sent: list[PingRow] = []
        owner: list[int] = []
        duplicates = [0] * len(group)
        conflicts: list[list[PingKey]] = [[] for _ in group]
        first: dict[PingKey, PingRow] = {}
        for number, submission in enumerate(group):
            for row in submission.rows:
                key = (row.vehicle_id, row.ts)
                kept = first.get(key)
                if kept is not None:
                    duplicates[number] += 1
                    if _content(kept) != _content(row):
                        conflicts[number].append(key)
                    continue
                first[key] = row
                sent.append(row)
                owner.append(number)
        # In key order: two groups holding the same pings (a car resending to another replica,
        # an operator's bulk upload) take their index locks in one order. In arrival order
        # PostgreSQL found a deadlock and aborted one, and its cars read that as an outage.
        order = sorted(range(len(sent)), key=lambda i: (sent[i].vehicle_id, sent[i].ts))
        sent = [sent[i] for i in order]
        owner = [owner[i] for i in order]
        started = time.perf_counter()
        values = [
            (*row[: _LANE + 1], position, *row[_LANE + 1 : -1])
            for row, position in zip(sent, _map_match(sent), strict=True)
        ]
        connection = self._idle.pop() if self._idle else await self._connect()
        try:
            pooled = await connection.get_raw_connection()
            driver = pooled.driver_connection
            assert isinstance(driver, psycopg.AsyncConnection)
            if len(values) <= SMALL_GROUP_ROWS:
                already_stored = await _insert_small(driver, values)
            else:
                already_stored = await _copy_large(driver, values, pooled.info)
            conflicting = (
                await _conflicting(driver, values, already_stored) if already_stored else set()
            )
        except BaseException:
            with contextlib.suppress(Exception):
                await connection.invalidate()
                await connection.close()
            raise
        self._idle.append(connection)
        metrics.PING_GROUP_ROWS.observe(len(sent))
        metrics.PING_GROUP_SECONDS.observe(time.perf_counter() - started)
        accepted = [0] * len(group)
        for position, number in enumerate(owner):
            if position in already_stored:
                duplicates[number] += 1
                if position in conflicting:
                    conflicts[number].append((sent[position].vehicle_id, sent[position].ts))
            else:
                accepted[number] += 1
        return [
            WriteOutcome(a, d, tuple(c))
            for a, d, c in zip(accepted, duplicates, conflicts, strict=True)
        ]


def _content(row: PingRow) -> tuple[object, ...]:
    """What the car said in a ping beside its key."""
    return tuple(row[position] for position in _CONTENT)


Values = tuple[object, ...]


async def _insert_small(driver: psycopg.AsyncConnection[Any], values: Sequence[Values]) -> set[int]:
    """Write a small group in one statement that commits; the positions already stored.

    The statement sends floats as float8, which PostgreSQL's cast to a REAL column refuses as
    "underflow" when the value is too small to keep; COPY's binary float4 stores such a value
    as 0, and so does this path (pings are not checked against it: contract.vehicles.Ping).
    """
    parameters: list[object] = []
    for row in values:
        parameters.extend(_as_stored(row))
    async with psycopg.AsyncRawCursor(driver) as cursor:
        await cursor.execute(insert_values(len(values)), parameters)
        inserted = {(vehicle_id, ts) for vehicle_id, ts in await cursor.fetchall()}
    return {n for n, row in enumerate(values) if (row[0], row[1]) not in inserted}


def _as_stored(row: Values) -> list[object]:
    """A written row's values with a float too small for a REAL as 0, as COPY stores it."""
    fields = list(row)
    for position in _FLOAT4:
        value = fields[position]
        if isinstance(value, float) and value != 0.0 and abs(value) < NEGLIGIBLE:
            fields[position] = 0.0
    return fields


async def _conflicting(
    driver: psycopg.AsyncConnection[Any], values: Sequence[Values], already_stored: set[int]
) -> set[int]:
    """Of the positions already stored, those whose stored row says something else than the
    row sent (a car's clock stamping two pings alike); one statement, run only on resends."""
    positions = sorted(already_stored)
    rows = [_as_stored(values[position]) for position in positions]
    columns = [positions, *([row[n] for row in rows] for n in _WRITTEN_KEY_AND_CONTENT)]
    async with psycopg.AsyncRawCursor(driver) as cursor:
        await cursor.execute(CONFLICTING, columns)
        return {n for (n,) in await cursor.fetchall()}


async def _copy_large(
    driver: psycopg.AsyncConnection[Any], values: Sequence[Values], info: dict[object, object]
) -> set[int]:
    """Write a large group by COPY; the positions already stored (app.ingest.sql)."""
    try:
        async with driver.transaction(), driver.cursor() as cursor:
            async with cursor.copy(COPY_STORED) as copy:
                copy.set_types(COPY_TYPES[1:])
                for row in values:
                    await copy.write_row(row)
        return set()
    except psycopg.errors.UniqueViolation:
        pass  # some rows were stored before: the temporary table tells which
    async with driver.cursor() as cursor:
        if "ping_incoming" not in info:
            await cursor.execute(CREATE_INCOMING)
            info["ping_incoming"] = True
        async with driver.transaction():
            async with cursor.copy(COPY_INCOMING) as copy:
                copy.set_types(COPY_TYPES)
                for number, row in enumerate(values):
                    await copy.write_row((number, *row))
            await cursor.execute(INSERT_FROM_INCOMING)
            return {n for (n,) in await cursor.fetchall()}


def _fail(group: Sequence[_Submission], error: Exception) -> None:
    for submission in group:
        if not submission.answer.done():
            submission.answer.set_exception(error)


# COPY names a refused value's column in its error context: "COPY ping_incoming, line 3,
# column controller: ...".
_COPY_COLUMN = re.compile(r"column (\w+)")
_TEXT_FIELDS = tuple(
    (PingRow._fields.index(name), name) for name, pg_type in PING_COLUMNS if pg_type == "text"
)


def _refusal(error: Exception, rows: Sequence[PingRow]) -> RefusedByDatabase:
    """What a lone request is told when its rows were refused, naming the field if known."""
    for row in rows:
        for position, name in _TEXT_FIELDS:
            value = row[position]
            if not isinstance(value, str):
                continue
            if "\x00" in value:
                return UnstorableValue(name, "text holds a NUL (0x00) character")
            if not value.isascii():
                try:
                    value.encode()
                except UnicodeEncodeError:
                    return UnstorableValue(name, "text holds a lone UTF-16 surrogate")
    if isinstance(error, UnicodeEncodeError):
        return UnstorableValue("text", "text holds a lone UTF-16 surrogate")
    assert isinstance(error, psycopg.Error)
    reason = error.diag.message_primary or type(error).__name__
    if isinstance(error, psycopg.DataError):
        column = _COPY_COLUMN.search(error.diag.context or "")
        return UnstorableValue(column.group(1) if column else "value", reason)
    return RefusedByDatabase(reason)


def _map_match(rows: Sequence[PingRow]) -> list[float | None]:
    """x_m of each row on its corridor, its vehicle's at the ping's ts (vectorised per
    corridor, but fix by fix for the few fixes of a small group)."""
    x_m: list[float | None] = [None] * len(rows)
    by_corridor: dict[str, list[int]] = {}
    for position, row in enumerate(rows):
        by_corridor.setdefault(row.corridor.corridor_id, []).append(position)
    for positions in by_corridor.values():
        corridor = rows[positions[0]].corridor
        if len(positions) <= SCALAR_MATCH_FIXES:
            for p in positions:
                row = rows[p]
                x_m[p] = corridor.x_m_of_fix(row.lat, row.lon, row.heading_deg, row.speed_mps)
            continue
        lat = np.fromiter((rows[p].lat for p in positions), dtype=np.float64, count=len(positions))
        lon = np.fromiter((rows[p].lon for p in positions), dtype=np.float64, count=len(positions))
        heading = trusted_heading(
            np.fromiter(
                (np.nan if rows[p].heading_deg is None else rows[p].heading_deg for p in positions),
                dtype=np.float64,
                count=len(positions),
            ),
            np.fromiter((rows[p].speed_mps for p in positions), np.float64, len(positions)),
        )
        for position, value in zip(positions, corridor.x_m(lat, lon, heading), strict=True):
            x_m[position] = value
    return x_m
