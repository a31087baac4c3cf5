"""What the API's per-request layers cost: RequestDeadline and RequestMetrics against a bare app.

    .venv/bin/python -m bench.middleware [--requests 100000]

Each layer wraps the same trivial ASGI app (read the body, answer 200) and is called as uvicorn
calls it, on uvloop, one request after another; the bare app is the baseline, measured in the
same run. Metrics run in Prometheus multiprocess mode, as `smoothfleet serve` runs them with
several workers (every value a write to a per-process file). Figures: us per request, best of
3 rounds.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

# Multiprocess mode is chosen when prometheus_client is first imported: before app.core.metrics.
os.environ["PROMETHEUS_MULTIPROC_DIR"] = tempfile.mkdtemp(prefix="sf-bench-metrics-")

import uvloop  # noqa: E402
from starlette.types import ASGIApp, Message, Receive, Scope, Send  # noqa: E402

from app.core.deadline import DatabaseWatch, RequestDeadline  # noqa: E402
from app.core.metrics import RequestMetrics  # noqa: E402

SCOPE: Scope = {"type": "http", "method": "POST", "path": "/api/v1/pings", "headers": []}


async def bare(scope: Scope, receive: Receive, send: Send) -> None:
    await receive()
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"{}"})


async def receive() -> Message:
    return {"type": "http.request", "body": b"{}", "more_body": False}


async def send(message: Message) -> None:
    return None


async def per_request_us(app: ASGIApp, requests: int) -> float:
    best = float("inf")
    for _ in range(3):
        started = time.perf_counter()
        for _ in range(requests):
            await app(SCOPE, receive, send)
        best = min(best, (time.perf_counter() - started) / requests * 1e6)
    return best


async def measure(requests: int) -> None:
    # The watch is never asked: no request here reaches its deadline.
    watch = DatabaseWatch("postgresql+psycopg://nobody@127.0.0.1:9/nothing", 0.7)
    layers: dict[str, ASGIApp] = {
        "bare app (baseline)": bare,
        "RequestDeadline": RequestDeadline(bare, deadline_s=0.8, watch=watch),
        "RequestMetrics": RequestMetrics(bare),
    }
    base = 0.0
    print("| layer | us per request | over the bare app |")
    print("|---|---:|---:|")
    for name, app in layers.items():
        us = await per_request_us(app, requests)
        base = base or us
        print(f"| {name} | {us:.2f} | {us - base:+.2f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--requests", type=int, default=100_000, help="requests per round")
    args = parser.parse_args()
    uvloop.run(measure(args.requests))


if __name__ == "__main__":
    main()
