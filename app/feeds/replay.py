"""Replay recorded snapshots in the order they were received, at real time or faster."""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable, Sequence

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
