"""The real app on a socket with an httpx client, and ping payloads for the ingest tests."""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx

from tests.support.servers import live_server

# A point on I-24-WB: the start vertex of sub-segment 11 of the seed corridor (x_m = 900.38).
ON_CORRIDOR = {"lat": 35.9801988, "lon": -86.5757771}
ON_CORRIDOR_X_M = 900.38
# Downtown Murfreesboro, ~8 km from the corridor.
OFF_CORRIDOR = {"lat": 35.8456, "lon": -86.3903}

_seconds = itertools.count(1)
_START = datetime.now(UTC).replace(microsecond=0)


@contextmanager
def serving(database_url: str, **settings: Any) -> Iterator[httpx.Client]:
    """A client on the real app serving `database_url`."""
    with (
        live_server(database_url, **settings) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        yield client


def fresh_ts() -> datetime:
    """A distinct recent timestamp per call (whole seconds back from the session's start)."""
    return _START - timedelta(seconds=next(_seconds))


def ping(
    vehicle_id: str = "SF-001", ts: datetime | str | None = None, **fields: Any
) -> dict[str, Any]:
    """A valid ping of the vehicle on the corridor, with `fields` overriding (ts may be text)."""
    ts = ts or fresh_ts()
    body: dict[str, Any] = {
        "vehicle_id": vehicle_id,
        "ts": ts if isinstance(ts, str) else ts.isoformat(),
        **ON_CORRIDOR,
        "speed_mps": 24.5,
    }
    body.update(fields)
    return body
