"""`smoothfleet inrix poll`: each period, retries with backoff, the key never shown; replays."""

from __future__ import annotations

import asyncio
import logging
import subprocess
import sys
import threading
from collections.abc import AsyncIterator, Awaitable, Callable, Iterator
from datetime import UTC, datetime, timedelta
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import httpx
import orjson
import pytest
from pydantic import SecretStr
from sqlalchemy import Engine, text

from app.feeds.poller import InrixPoller, PollFailed, StoreFailed
from app.feeds.recording import (
    RecordedSnapshot,
    append_to_recording,
    read_recording,
    snapshots_from_drive,
)
from app.feeds.replay import live_offset, replay
from tests.support.servers import cli_env, run_cli

KEY = "inrix-key-7f3a9c"


class FakeClock:
    """Time that moves only when the code under test sleeps."""

    def __init__(self) -> None:
        self.now = 1000.0
        self.sleeps: list[float] = []

    def __call__(self) -> float:
        return self.now

    async def sleep(self, seconds: float) -> None:
        self.sleeps.append(seconds)
        self.now += seconds
        await asyncio.sleep(0)  # other tasks run, as they would during a real sleep


class Provider:
    """A stand-in INRIX endpoint on a real socket: fails `failures` times, then answers."""

    def __init__(self, body: bytes, failures: int) -> None:
        self.body = body
        self.failures = failures
        self.authorizations: list[str | None] = []
        self.paths: list[str] = []

    @property
    def handler(self) -> type[BaseHTTPRequestHandler]:
        provider = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:  # noqa: N802 - http.server's naming
                provider.authorizations.append(self.headers.get("Authorization"))
                provider.paths.append(self.path)
                if len(provider.authorizations) <= provider.failures:
                    self.send_response(503)
                    self.end_headers()
                    return
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(provider.body)))
                self.end_headers()
                self.wfile.write(provider.body)

            def log_message(self, *args: object) -> None:
                pass

        return Handler


@pytest.fixture
def snapshot(shared_dir: Path) -> RecordedSnapshot:
    drive = next((shared_dir / "data/trajectories_with_inrix").glob("2021-04-22*masterArray_1*"))
    return snapshots_from_drive(drive)[0]


@pytest.fixture
def provider(snapshot: RecordedSnapshot) -> Iterator[tuple[Provider, str]]:
    fake = Provider(orjson.dumps(snapshot.response), failures=2)
    server = ThreadingHTTPServer(("127.0.0.1", 0), fake.handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield fake, f"http://127.0.0.1:{server.server_address[1]}/v1/segments/speed?corridor=I-24"
    finally:
        server.shutdown()
        server.server_close()


def test_poll_retries_until_the_provider_answers_and_never_shows_the_key(
    provider: tuple[Provider, str],
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
) -> None:
    fake, url = provider
    recording = tmp_path / "polled.jsonl"
    env = cli_env(
        SMOOTHFLEET_DATABASE_URL=seeded_database_url,
        SMOOTHFLEET_INRIX_URL=url,
        SMOOTHFLEET_INRIX_KEY=KEY,
    )

    result = run_cli("inrix", "poll", "--count", "1", "--record", str(recording), env=env)

    assert result.returncode == 0, result.stderr
    assert fake.authorizations == [f"Bearer {KEY}"] * 3
    assert all(KEY not in path for path in fake.paths)
    assert "provider answered HTTP 503; retrying in 1 s" in result.stderr
    assert "retrying in 2 s" in result.stderr
    assert KEY not in result.stdout + result.stderr
    assert result.stdout.startswith("2021-04-22T13:31:00+00:00: 18 stored, 0 already stored")
    with seeded_engine.connect() as connection:
        count = connection.execute(text("SELECT count(*) FROM fact_inrix_estimate")).scalar()
    assert count == 18
    [recorded] = read_recording(recording)
    assert recorded.response["result"]["segmentspeeds"][0]["timestamp"] == (
        "2021-04-22T13:31:00.000Z"
    )


def test_a_recording_that_cannot_be_written_stops_recording_not_polling(
    provider: tuple[Provider, str], seeded_database_url: str, tmp_path: Path
) -> None:
    """A full disk under the recording (/dev/full answers every write with ENOSPC) must not end
    the feed the planner reads: both snapshots are still polled and stored."""
    fake, url = provider
    recording = tmp_path / "polled.jsonl"
    recording.symlink_to("/dev/full")
    env = cli_env(
        SMOOTHFLEET_DATABASE_URL=seeded_database_url,
        SMOOTHFLEET_INRIX_URL=url,
        SMOOTHFLEET_INRIX_KEY=KEY,
        SMOOTHFLEET_INRIX_POLL_PERIOD_S="0.1",
    )

    result = run_cli("inrix", "poll", "--count", "2", "--record", str(recording), env=env)

    assert result.returncode == 0, result.stderr
    assert len(fake.authorizations) == 2 + 2  # the two failures, then two snapshots
    assert f"recording to {recording} failed (No space left on device)" in result.stderr
    assert result.stderr.count("failed (No space left on device)") == 1
    assert "18 stored" in result.stdout
    assert "0 stored, 18 already stored" in result.stdout


def test_a_write_cut_short_leaves_the_recording_whole(
    snapshot: RecordedSnapshot, tmp_path: Path
) -> None:
    """A disk filling up mid-line left the bytes written, and `read_recording` refused the
    whole file for the cut line. The append is undone to the last whole line. (A file-size
    limit stands in for the full disk, in a process of its own: Python ignores SIGXFSZ, so
    the write raises EFBIG once the limit is reached.)"""
    recording = tmp_path / "polled.jsonl"
    append_to_recording(recording, snapshot)
    whole = recording.read_bytes()
    script = (
        "import resource, sys\n"
        "from pathlib import Path\n"
        "from app.feeds.recording import append_to_recording, read_recording\n"
        "path = Path(sys.argv[1])\n"
        "[snapshot] = read_recording(path)\n"
        "limit = path.stat().st_size + 1000  # room for part of a second line only\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))\n"
        "try:\n"
        "    append_to_recording(path, snapshot)\n"
        "except OSError as error:\n"
        "    print(error.strerror)\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script, str(recording)],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=Path(__file__).resolve().parents[2],
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "File too large"
    assert recording.read_bytes() == whole
    assert len(read_recording(recording)) == 1


@pytest.mark.parametrize("missing", ["SMOOTHFLEET_INRIX_URL", "SMOOTHFLEET_INRIX_KEY"])
def test_poll_without_url_or_key_is_one_line_naming_it(
    seeded_database_url: str, missing: str
) -> None:
    settings = {
        "SMOOTHFLEET_DATABASE_URL": seeded_database_url,
        "SMOOTHFLEET_INRIX_URL": "http://127.0.0.1:9/",
        "SMOOTHFLEET_INRIX_KEY": KEY,
    }
    del settings[missing]
    result = run_cli("inrix", "poll", "--count", "1", env=cli_env(**settings))
    assert result.returncode == 1
    assert (
        result.stderr.strip()
        == f"smoothfleet: error: {missing}: must be set for `smoothfleet inrix poll`"
    )


def test_backoff_doubles_and_gives_up_when_the_next_period_starts(
    snapshot: RecordedSnapshot,
) -> None:
    clock = FakeClock()
    calls: list[float] = []
    body = orjson.dumps(snapshot.response)

    def answer(request: httpx.Request) -> httpx.Response:
        calls.append(clock.now)
        # Down for the whole first period (60 s) and the first try of the second.
        if clock.now < 1061:
            return httpx.Response(502)
        return httpx.Response(200, content=body)

    handled: list[RecordedSnapshot] = []

    async def handle(recorded: RecordedSnapshot) -> None:
        handled.append(recorded)

    assert polling(snapshot, clock, answer, handle, count=2) == 2
    # First period: tries at 0, 1, 3, 7, 15, 31 s (retry waits 1, 2, 4, 8, 16); the next wait
    # (30 s, capped) would cross into the second period, so it waits for that period instead.
    offsets = [round(moment - 1000) for moment in calls]
    assert offsets[:6] == [0, 1, 3, 7, 15, 31]
    # Second period begins at 60 s: fails once, succeeds after 1 s; the third period at 120 s.
    assert offsets[6:] == [60, 61, 120]
    assert len(handled) == 2


def test_a_response_over_the_cap_is_refused_without_reading_it_whole() -> None:
    """A 200 MB body was read whole, on every retry: 3 GB on a host shared with PostgreSQL
    (ops audit)."""
    served: list[int] = []

    async def endless() -> AsyncIterator[bytes]:
        for _ in range(1000):  # 64 MB if read to the end
            served.append(1)
            yield b" " * 65536

    def answer(request: httpx.Request) -> httpx.Response:
        if request.url.path == "/announced":
            return httpx.Response(200, headers={"Content-Length": str(10**9)}, content=endless())
        return httpx.Response(200, content=endless())

    async def fetch(path: str) -> str:
        async with httpx.AsyncClient(transport=httpx.MockTransport(answer)) as client:
            poller = InrixPoller(
                f"http://provider.test{path}",
                SecretStr(KEY),
                period_s=60,
                client=client,
                max_response_bytes=2**20,
            )
            with pytest.raises(PollFailed) as refused:
                await poller.fetch()
            return str(refused.value)

    message = asyncio.run(fetch("/streamed"))
    assert message == (
        "provider answered more than 1,048,576 bytes: not read (a corridor's response is kilobytes)"
    )
    assert len(served) <= 17  # 1 MB and one chunk, not 64 MB
    served.clear()
    assert asyncio.run(fetch("/announced")) == message
    assert served == []  # refused on its Content-Length, before a byte


def test_replay_keeps_the_recorded_spacing_divided_by_the_speed() -> None:
    start = datetime(2021, 3, 15, 13, 18, tzinfo=UTC)
    snapshots = [
        RecordedSnapshot(start + timedelta(seconds=offset), {"n": offset})
        for offset in (0, 60, 60, 180)
    ]
    clock = FakeClock()
    handed: list[tuple[float, object]] = []

    async def handle(snapshot: RecordedSnapshot) -> None:
        handed.append((clock.now - 1000, snapshot.response["n"]))

    assert asyncio.run(replay(snapshots, handle, speed=10, sleep=clock.sleep, clock=clock)) == 4
    assert handed == [(0, 0), (6, 60), (6, 60), (18, 180)]

    fast = FakeClock()
    asyncio.run(replay(snapshots, handle, speed=0, sleep=fast.sleep, clock=fast))
    assert fast.sleeps == []


@pytest.mark.parametrize("speed", [0.5, 1.0, 10.0, 0.0])
def test_a_replay_shifted_to_now_never_stamps_a_snapshot_after_it_is_stored(speed: float) -> None:
    """The planner ignores readings from its future: a live replay must not stamp any ahead of
    the moment it stores it, and (for the largest such shift) one is stamped exactly then."""
    start = datetime(2021, 3, 15, 13, 18, tzinfo=UTC)
    snapshots = [RecordedSnapshot(start + timedelta(minutes=k), {}) for k in range(13)]
    now = datetime(2026, 12, 2, 9, 0, tzinfo=UTC)
    offset = live_offset(snapshots, speed, now)
    lags = []
    for snapshot in snapshots:
        elapsed = (snapshot.recorded_at - start) / speed if speed else timedelta(0)
        lags.append(now + elapsed - (snapshot.recorded_at + offset))
    assert min(lags) == timedelta(0)
    stamped_now = {1.0: 0, 0.5: 0, 10.0: 12, 0.0: 12}[speed]
    assert lags[stamped_now] == timedelta(0)


def polling(
    snapshot: RecordedSnapshot,
    clock: FakeClock,
    answer: Callable[[httpx.Request], Any],
    store: Callable[[RecordedSnapshot], Awaitable[None]],
    *,
    count: int,
    record: Callable[[RecordedSnapshot], None] | None = None,
    **limits: float,
) -> int:
    """Run a poller on `answer` (a provider) and `store` with the fake clock's backoff."""

    async def run() -> int:
        async with httpx.AsyncClient(transport=httpx.MockTransport(answer)) as client:
            poller = InrixPoller(
                "http://provider.test/speed",
                SecretStr(KEY),
                period_s=60,
                client=client,
                sleep=clock.sleep,
                clock=clock,
                **limits,  # type: ignore[arg-type]
            )
            return await poller.run(store, record=record, count=count)

    return asyncio.run(run())


def test_what_is_fetched_while_the_database_is_down_is_recorded_and_stored_once_it_is_back(
    snapshot: RecordedSnapshot, caplog: pytest.LogCaptureFixture
) -> None:
    """INRIX serves the current minute only: a poll that fetched a response and could not
    store it threw it away and asked the provider again (6 calls a minute), and recorded it
    only after storing, so an outage left a hole in the warehouse and in the recording that
    should backfill it. Down for 100 s, the database misses no minute now."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    fetched_at: list[float] = []
    recorded: list[RecordedSnapshot] = []
    stored: list[RecordedSnapshot] = []

    def answer(request: httpx.Request) -> httpx.Response:
        fetched_at.append(clock.now)
        return httpx.Response(200, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        if clock.now < 1100:
            raise StoreFailed("database: connection refused")
        stored.append(recorded_snapshot)

    caplog.set_level(logging.WARNING, logger="app.feeds.poller")
    assert polling(snapshot, clock, answer, store, count=3, record=recorded.append) == 3
    # one request a period (0, 60, 120 s), recorded at once; stored in order at 120 s
    assert [round(moment - 1000) for moment in fetched_at] == [0, 60, 120]
    assert [id(item) for item in stored] == [id(item) for item in recorded]
    assert len(stored) == 3
    assert "INRIX snapshot not stored: database: connection refused (2 kept to store)" in (
        caplog.text
    )


def test_minutes_kept_while_the_database_was_down_are_stored_while_the_provider_is_down(
    snapshot: RecordedSnapshot, caplog: pytest.LogCaptureFixture
) -> None:
    """The database comes back as the provider goes away: the minute kept waits for the
    database only, not for the provider to answer again."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    stored_at: list[float] = []

    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200 if clock.now < 1060 else 502, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        if clock.now < 1060:
            raise StoreFailed("database: connection refused")
        stored_at.append(clock.now)

    caplog.set_level(logging.WARNING, logger="app.feeds.poller")
    assert polling(snapshot, clock, answer, store, count=1) == 1
    # stored at 60 s, on the period's first try, though the provider answered 502 to it
    assert [round(moment - 1000) for moment in stored_at] == [60]


def test_a_provider_that_never_finishes_answering_is_given_up_at_the_deadline(
    snapshot: RecordedSnapshot, caplog: pytest.LogCaptureFixture
) -> None:
    """httpx's timeout bounds each read, not the request: a provider sending a byte now and
    then held the poller for as long as it liked, and no minute was polled meanwhile."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    calls: list[float] = []

    async def answer(request: httpx.Request) -> httpx.Response:
        calls.append(clock.now)
        if len(calls) == 1:
            await asyncio.sleep(3600)
        return httpx.Response(200, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        pass

    caplog.set_level(logging.WARNING, logger="app.feeds.poller")
    assert polling(snapshot, clock, answer, store, count=1, fetch_deadline_s=0.2) == 1
    assert [round(moment - 1000) for moment in calls] == [0, 1]
    assert "provider did not answer within 0.2 s; retrying in 1 s" in caplog.text


def test_a_store_the_database_never_answers_is_given_up_and_no_other_starts_until_it_ends(
    snapshot: RecordedSnapshot, caplog: pytest.LogCaptureFixture
) -> None:
    """A frozen database never enforces its statement timeout: the store hung, and the feed
    with it. Now it is given up after the deadline and cancelled; while its clean-up still
    waits on the server, no second store piles up on it; once it ends, the snapshot it held is
    stored (fetched once)."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    calls: list[float] = []
    stores: list[float] = []
    cleaned_up = asyncio.Event()

    def answer(request: httpx.Request) -> httpx.Response:
        calls.append(clock.now)
        return httpx.Response(200, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        stores.append(clock.now)
        if len(stores) == 1:
            try:
                await asyncio.sleep(3600)
            except asyncio.CancelledError:
                await cleaned_up.wait()  # a clean-up waiting on the same server

    async def sleep(seconds: float) -> None:
        await FakeClock.sleep(clock, seconds)
        if clock.now >= 1030:
            cleaned_up.set()
            await asyncio.sleep(0)

    clock.sleep = sleep  # type: ignore[method-assign]
    caplog.set_level(logging.WARNING, logger="app.feeds.poller")
    assert polling(snapshot, clock, answer, store, count=1, store_deadline_s=0.2) == 1
    assert [round(moment - 1000) for moment in calls] == [0]
    # given up at once, then refused at 1, 3, 7 and 15 s while it cleans up; stored at 31 s
    assert [round(moment - 1000) for moment in stores] == [0, 31]
    assert "the database did not answer within 0.2 s (1 kept to store)" in caplog.text
    assert caplog.text.count("has not ended the store given up on before") == 4


def test_a_database_error_in_a_store_is_a_store_failure_not_a_poll_failure(
    snapshot: RecordedSnapshot,
) -> None:
    """The CLI's store tells a database that does not take a snapshot (kept, stored later)
    from a response that is no usable snapshot (dropped, asked again)."""
    from sqlalchemy.ext.asyncio import async_sessionmaker

    from app.core.db import make_async_engine
    from smoothfleet.cli.inrix import _storer

    async def run() -> None:
        engine = make_async_engine("postgresql+psycopg://nobody@127.0.0.1:9/none", pool_size=1)
        try:
            store = _storer(async_sessionmaker(engine), lambda item: timedelta(0), 300.0)
            with pytest.raises(StoreFailed, match="^database: "):
                await store(snapshot)
            with pytest.raises(PollFailed):
                await store(RecordedSnapshot(snapshot.recorded_at, {"result": []}))
        finally:
            await engine.dispose()

    asyncio.run(run())


def test_a_provider_asking_to_wait_is_left_alone_that_long(snapshot: RecordedSnapshot) -> None:
    """A 429 with Retry-After: 300 for 5 minutes drew 31 requests (the back-off restarted at
    1 s every period); a refused key (401) was asked 6 times a minute. Now: none before the
    wait is over, and one a period for an answer asking again cannot change."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    asked_at: list[float] = []

    def limited(request: httpx.Request) -> httpx.Response:
        asked_at.append(clock.now - 1000)
        if clock.now < 1300:
            return httpx.Response(429, headers={"Retry-After": "300"})
        return httpx.Response(200, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        return None

    assert polling(snapshot, clock, limited, store, count=1) == 1
    assert asked_at == [0, 300]
    asked_at.clear()
    clock = FakeClock()

    def refusing(request: httpx.Request) -> httpx.Response:
        asked_at.append(clock.now - 1000)
        return httpx.Response(200 if clock.now >= 1180 else 401, content=body)

    assert polling(snapshot, clock, refusing, store, count=1) == 1
    assert asked_at == [0, 60, 120, 180]


def test_a_period_overrun_skips_the_periods_it_covered(snapshot: RecordedSnapshot) -> None:
    """Two stores taking 90 s of a 60 s period: the next poll was due in the past, and once the
    database recovered the poller asked back to back to catch up (0 s apart)."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    asked_at: list[float] = []

    def answer(request: httpx.Request) -> httpx.Response:
        asked_at.append(clock.now - 1000)
        return httpx.Response(200, content=body)

    async def slow_store(recorded_snapshot: RecordedSnapshot) -> None:
        if len(asked_at) <= 2:  # the first two stores take 90 s, then the database recovers
            await clock.sleep(90.0)

    assert polling(snapshot, clock, answer, slow_store, count=4) == 4
    gaps = [later - earlier for earlier, later in zip(asked_at, asked_at[1:], strict=False)]
    assert min(gaps) >= 60.0


def test_a_counted_poll_stores_every_minute_it_fetched_before_it_stops(
    snapshot: RecordedSnapshot,
) -> None:
    """`inrix poll --count 2` after 3 minutes without a database stored minutes 0 and 1 and
    exited, minutes 2 and 3 fetched and never stored."""
    clock = FakeClock()
    body = orjson.dumps(snapshot.response)
    stored: list[float] = []

    def answer(request: httpx.Request) -> httpx.Response:
        return httpx.Response(200, content=body)

    async def store(recorded_snapshot: RecordedSnapshot) -> None:
        if clock.now < 1180:
            raise StoreFailed("database: connection refused")
        stored.append(clock.now)

    assert polling(snapshot, clock, answer, store, count=2) == 4
    assert len(stored) == 4
