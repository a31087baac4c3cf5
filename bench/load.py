"""Load for bench/ingest.py: pings at a constant offered rate, latency free of coordinated omission.

A closed-loop load (each connection sends its next request when the last is answered) slows
down when the server stalls, so the requests that would have waited are never sent and a stall
hides from the percentiles (coordinated omission). Here request i is due at t0 + i / rate
whatever happened before, and its latency runs from when it was due, not from when it could be
sent: a stall shows in every request it delayed. HTTP/1.1 keep-alive over raw asyncio streams
(one request at a time per connection, a new connection when all are busy) keeps the
generator's own cost small next to the server's. The load stands for `rate` cars pinging once a
second, so it holds at most `rate` connections, one per car: a server slower than the offered
rate makes requests wait for a connection (their latency still runs from when they were due)
instead of the generator opening connections without end (it once ran out of file descriptors
at 20,000 when a server fell behind 2,000 pings/s for 20 s).

`saturate` is the closed loop, for throughput at saturation: `connections` clients back to back.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import urlsplit

import numpy as np

Body = Callable[[int], bytes]


@dataclass(frozen=True)
class Latencies:
    """What one load slice saw: latencies (s) of answered requests and the count of errors."""

    seconds: np.ndarray
    non_2xx: int
    duration_s: float

    @property
    def rate(self) -> float:
        return len(self.seconds) / self.duration_s


class _Connection:
    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer

    async def post(self, head: bytes, body: bytes) -> int:
        self.writer.write(head + str(len(body)).encode() + b"\r\n\r\n" + body)
        status_line = await self.reader.readline()
        if not status_line:
            raise ConnectionResetError("the server closed this keep-alive connection")
        length = 0
        while True:
            line = await self.reader.readline()
            if line in (b"\r\n", b""):
                break
            name, _, value = line.partition(b":")
            if name.strip().lower() == b"content-length":
                length = int(value)
        await self.reader.readexactly(length)
        return int(status_line.split()[1])


async def _connect(host: str, port: int) -> _Connection:
    reader, writer = await asyncio.open_connection(host, port)
    return _Connection(reader, writer)


def _head(url: str, token: str) -> tuple[str, int, bytes]:
    parts = urlsplit(url)
    head = (
        f"POST {parts.path} HTTP/1.1\r\nHost: {parts.netloc}\r\n"
        f"Authorization: Bearer {token}\r\nContent-Type: application/json\r\nContent-Length: "
    ).encode()
    return parts.hostname or "127.0.0.1", parts.port or 80, head


async def constant_rate(
    url: str, token: str, body: Body, *, rate: float, duration_s: float
) -> Latencies:
    """POST `body(i)` for i = 0, 1, ... at `rate` per second for `duration_s`."""
    host, port, head = _head(url, token)
    idle: list[_Connection] = []
    latencies: list[float] = []
    errors = 0
    total = int(rate * duration_s)
    cars = asyncio.Semaphore(max(1, round(rate)))  # one connection per car

    async def one(i: int, due: float) -> None:
        nonlocal errors
        async with cars:
            connection = idle.pop() if idle else await _connect(host, port)
            try:
                status = await connection.post(head, body(i))
            except ConnectionError:  # closed while idle (keep-alive timeout): never read, resend
                connection = await _connect(host, port)
                status = await connection.post(head, body(i))
            latencies.append(time.perf_counter() - due)
            if status >= 300:
                errors += 1
            idle.append(connection)

    started = time.perf_counter()
    tasks = []
    for i in range(total):
        due = started + i / rate
        wait = due - time.perf_counter()
        if wait > 0:
            await asyncio.sleep(wait)
        tasks.append(asyncio.create_task(one(i, due)))
    await asyncio.gather(*tasks)
    for connection in idle:
        connection.writer.close()
    return Latencies(np.array(latencies), errors, duration_s)


async def saturate(
    url: str, token: str, body: Body, *, connections: int, duration_s: float
) -> Latencies:
    """`connections` clients posting back to back for `duration_s`."""
    host, port, head = _head(url, token)
    latencies: list[float] = []
    errors = 0
    counter = iter(range(10**9))
    stop_at = time.perf_counter() + duration_s

    async def client() -> None:
        nonlocal errors
        connection = await _connect(host, port)
        while time.perf_counter() < stop_at:
            began = time.perf_counter()
            status = await connection.post(head, body(next(counter)))
            latencies.append(time.perf_counter() - began)
            if status >= 300:
                errors += 1
        connection.writer.close()

    started = time.perf_counter()
    await asyncio.gather(*(client() for _ in range(connections)))
    return Latencies(np.array(latencies), errors, time.perf_counter() - started)
