"""One car's unstorable ping never costs another car its ping.

Over HTTP the ping is refused at the edge (422 naming the field). Behind that,
pings of many requests are written in one group commit, and a row PostgreSQL refuses whatever
the checks let through must fail only the request holding it (the writer's own test, below),
while every other request of the group commits.
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections import Counter
from datetime import UTC, datetime, timedelta

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.db import make_async_engine
from app.ingest.directory import CorridorInfo
from app.ingest.pings import PingRow
from app.ingest.sql import SMALL_GROUP_ROWS
from app.ingest.writer import PingWriter, UnstorableValue, WriteOutcome
from tests.support.api import ping, serving
from tests.support.databases import sessions_waiting_on_a_lock
from tests.support.tokens import bearer, issue

CLEAN_CARS = 10
REQUESTS_PER_CAR = 30


def test_a_poison_car_gets_422s_and_the_clean_cars_only_200s(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    clean = {f"SF-{n:03d}": issue(seeded_engine, "vehicle", f"SF-{n:03d}") for n in range(2, 12)}
    poison_token = issue(seeded_engine, "vehicle", "SF-001")
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(hours=1)
    seen: dict[str, Counter[int]] = {vehicle: Counter() for vehicle in [*clean, "SF-001"]}
    poison_details: set[str] = set()
    stop = threading.Event()

    def clean_car(client: httpx.Client, vehicle: str, token: str) -> None:
        for second in range(REQUESTS_PER_CAR):
            body = ping(vehicle, start + timedelta(seconds=second))
            answer = client.post("/api/v1/pings", json=body, headers=bearer(token))
            seen[vehicle][answer.status_code] += 1

    def poison_car(client: httpx.Client) -> None:
        second = 0
        while not stop.is_set():
            body = ping("SF-001", start + timedelta(seconds=second), controller="a\u0000b")
            answer = client.post("/api/v1/pings", json=body, headers=bearer(poison_token))
            seen["SF-001"][answer.status_code] += 1
            # Refused at the edge: a lone ping that is not valid is 422, naming the field.
            poison_details.add(answer.json()["detail"])
            second += 1
            time.sleep(0.05)  # every 50 ms, as in the report (within the per-token rate)

    with serving(seeded_database_url) as client:
        poisoner = threading.Thread(target=poison_car, args=(client,))
        poisoner.start()
        cars = [
            threading.Thread(target=clean_car, args=(client, vehicle, token))
            for vehicle, token in clean.items()
        ]
        for car in cars:
            car.start()
        for car in cars:
            car.join()
        stop.set()
        poisoner.join()

    for vehicle in clean:
        assert seen[vehicle] == Counter({200: REQUESTS_PER_CAR}), (vehicle, seen[vehicle])
    assert set(seen["SF-001"]) == {422}
    assert poison_details == {
        "not a valid ping: controller: text must not contain the NUL character (\\u0000)"
    }
    with seeded_engine.connect() as connection:
        counts = dict(
            connection.execute(
                text("SELECT vehicle_id, count(*) FROM fact_vehicle_ping GROUP BY vehicle_id")
            ).all()
        )
    assert counts == dict.fromkeys(clean, REQUESTS_PER_CAR)


def _row(vehicle_id: str, ts: datetime, controller: str | None) -> PingRow:
    corridor = CorridorInfo("I-24-WB", 4, None)
    return PingRow(
        vehicle_id, ts, ts, 36.0, -86.6, 25.0, None, None, None, None, None, controller,
        None, None, None, None, None, None, None, corridor,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("poison", "reason"),
    [("a\u0000b", "0x00"), ("a\ud800b", "surrogate")],
    ids=["nul", "lone-surrogate"],
)
@pytest.mark.parametrize("bad_rows", [2, SMALL_GROUP_ROWS + 1], ids=["statement", "copy"])
def test_the_group_writer_fails_only_the_request_holding_an_unstorable_row(
    seeded_database_url: str, seeded_engine: Engine, poison: str, reason: str, bad_rows: int
) -> None:
    """The writer itself isolates a refused row, whatever the checks before it let through,
    in a group small enough for one statement and in one large enough for COPY."""
    ts = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    clean = [[_row(f"SF-{n:03d}", ts, "microaccel_acc")] for n in range(2, 9)]
    bad = [_row("SF-001", ts + timedelta(seconds=k), "microaccel_acc") for k in range(bad_rows)]
    bad[-1] = bad[-1]._replace(controller=poison)

    async def write_all() -> list[WriteOutcome | BaseException]:
        engine = make_async_engine(seeded_database_url)
        writer = PingWriter(engine, concurrency=1)
        writer.start()
        try:
            # Submitted together, so they form one group (written in one transaction).
            return await asyncio.gather(
                *(writer.write(rows) for rows in [*clean[:3], bad, *clean[3:]]),
                return_exceptions=True,
            )
        finally:
            await writer.stop()
            await engine.dispose()

    outcomes = asyncio.run(write_all())

    refusal = outcomes.pop(3)
    assert isinstance(refusal, UnstorableValue)
    assert refusal.field == "controller"
    assert reason in refusal.reason
    assert outcomes == [WriteOutcome(1, 0)] * len(clean)
    with seeded_engine.connect() as connection:
        stored = connection.execute(text("SELECT vehicle_id FROM fact_vehicle_ping")).scalars()
        assert sorted(stored) == sorted(rows[0].vehicle_id for rows in clean)


def test_groups_holding_the_same_pings_take_their_locks_in_one_order(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Two replicas writing the same pings in opposite orders (a car resending to another
    replica, an operator's bulk upload) deadlocked: PostgreSQL aborted one, and its cars read
    the abort as a database outage (503). Rows are written in key order, so a writer meeting a
    key another transaction holds waits on it before it holds any later key."""
    ts = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    first, second = ts, ts + timedelta(seconds=1)
    insert = text(
        "INSERT INTO fact_vehicle_ping (vehicle_id, ts, lat, lon, speed_mps) "
        "VALUES ('SF-001', :ts, 36.0, -86.6, 25.0)"
    )
    outcome: list[WriteOutcome | BaseException] = []

    async def write_in_arrival_order() -> None:
        engine = make_async_engine(seeded_database_url)
        writer = PingWriter(engine, concurrency=1)
        writer.start()
        try:
            rows = [_row("SF-001", second, None), _row("SF-001", first, None)]
            outcome.extend(await asyncio.gather(writer.write(rows), return_exceptions=True))
        finally:
            await writer.stop()
            await engine.dispose()

    with seeded_engine.connect() as other_replica:
        transaction = other_replica.begin()
        other_replica.execute(insert, {"ts": first})
        writing = threading.Thread(target=lambda: asyncio.run(write_in_arrival_order()))
        writing.start()
        waiting = sessions_waiting_on_a_lock(seeded_engine)
        assert waiting == 1
        other_replica.execute(insert, {"ts": second})  # a deadlock here, rows in arrival order
        transaction.commit()
        writing.join(timeout=30)
    assert outcome == [WriteOutcome(0, 2)]
