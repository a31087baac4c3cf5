"""Prometheus metrics of the API (served at /metrics) and the middleware timing requests.

Metrics are module-level, registered once per process. Labels are bounded: routes are the
declared path templates (unmatched paths share one label) and outcomes are fixed words.

With several uvicorn workers, `smoothfleet serve` points PROMETHEUS_MULTIPROC_DIR at a fresh
directory before the workers start: each worker then writes its values there and /metrics
(`exposition`) sums all workers, whichever of them answers the scrape.
"""

from __future__ import annotations

import os
import time

from prometheus_client import (
    REGISTRY,
    CollectorRegistry,
    Counter,
    Histogram,
    generate_latest,
    multiprocess,
)
from starlette.types import ASGIApp, Message, Receive, Scope, Send

PINGS = Counter(
    "smoothfleet_pings",
    "Pings received, by outcome (accepted, duplicate, rejected, refused = 403 request).",
    ["outcome"],
)
# Each outcome's series, made once: a ping request counts without a label lookup, and every
# outcome is exported from the start (at 0), so a rate over it never begins with a gap.
PINGS_ACCEPTED = PINGS.labels("accepted")
PINGS_DUPLICATE = PINGS.labels("duplicate")
PINGS_REJECTED = PINGS.labels("rejected")
PINGS_REFUSED = PINGS.labels("refused")
STATUS_REPORTS = Counter(
    "smoothfleet_status_reports", "piStatus reports received, by outcome.", ["outcome"]
)
INRIX_SEGMENTS = Counter(
    "smoothfleet_inrix_segments",
    "INRIX segment readings received, by outcome (stored, duplicate, unknown, refused).",
    ["outcome"],
)
REQUEST_SECONDS = Histogram(
    "smoothfleet_http_request_duration_seconds",
    "Time from request start to the end of the response, by route and status.",
    ["method", "route", "status"],
    buckets=(0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0),
)
PING_GROUP_ROWS = Histogram(
    "smoothfleet_ping_group_rows",
    "Pings per group-commit statement.",
    buckets=(1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000, 20000),
)
PING_GROUP_SECONDS = Histogram(
    "smoothfleet_ping_group_write_seconds",
    "Time to write and commit one group of pings.",
    buckets=(0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 5.0),
)

UNMATCHED_ROUTE = "unmatched"
MULTIPROCESS_DIR_ENV = "PROMETHEUS_MULTIPROC_DIR"


def server_registry() -> CollectorRegistry:
    """The metrics of this process, or of every worker when they share a directory."""
    if os.environ.get(MULTIPROCESS_DIR_ENV):
        registry = CollectorRegistry()
        multiprocess.MultiProcessCollector(registry)  # type: ignore[no-untyped-call]
        return registry
    return REGISTRY


def exposition() -> bytes:
    """The Prometheus text of `server_registry`."""
    return generate_latest(server_registry())


class RequestMetrics:
    """ASGI middleware observing every HTTP request's duration under its route template."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app
        # (method, route template, status) -> its histogram series: the label lookup once per
        # series instead of once per request (the ping endpoint is nearly every request).
        self._series: dict[tuple[str, str, int], Histogram] = {}

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        status = 500

        async def send_noting_status(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = message["status"]
            await send(message)

        try:
            await self.app(scope, receive, send_noting_status)
        finally:
            # The router stores the matched route in the (shared) scope.
            route = scope.get("route")
            template = getattr(route, "path", None) or UNMATCHED_ROUTE
            key = (scope["method"], template, status)
            series = self._series.get(key)
            if series is None:
                series = REQUEST_SECONDS.labels(key[0], template, str(status))
                self._series[key] = series
            series.observe(time.perf_counter() - started)
