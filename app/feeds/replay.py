"""Replay recorded snapshots in the order they were received, at real time or faster."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Sequence
from datetime import datetime, timedelta

from app.feeds.recording import RecordedSnapshot


async def replay(
    snapshots: Sequence[RecordedSnapshot],
    handle: Callable[[RecordedSnapshot], Awaitable[None]],
    *,
    speed: float = 1.0,
    sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
    clock: Callable[[], float] = time.monotonic,
) -> int:
    """Hand each snapshot over at its recorded offset divided by `speed` (0: no waiting)."""
    if speed < 0:
        raise ValueError("speed must be 0 (no waiting) or positive")
    if not snapshots:
        return 0
    first = snapshots[0].recorded_at
    started = clock()
    for snapshot in snapshots:
        if speed > 0:
            due = started + (snapshot.recorded_at - first).total_seconds() / speed
            wait = due - clock()
            if wait > 0:
                await sleep(wait)
        await handle(snapshot)
    return len(snapshots)


def live_offset(snapshots: Sequence[RecordedSnapshot], speed: float, now: datetime) -> timedelta:
    """The shift that stamps a replay as live data: the largest under which no snapshot is
    stamped after the moment `replay` stores it, so the planner (which ignores readings from
    its future) sees each one as it arrives. At speed 1 (or slower) the first snapshot is
    stamped now; faster, the replay is compressed and its stamps end at the moment it ends; at
    speed 0 (no waiting) the last is stamped now."""
    if not snapshots:
        return timedelta(0)
    first = snapshots[0].recorded_at
    span = snapshots[-1].recorded_at - first
    compressed = span if speed == 0 else span * max(0.0, 1.0 - 1.0 / speed)
    return now - first - compressed
