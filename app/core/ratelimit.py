"""Per-caller rate limits: a token bucket per key (token id, or client address at login).

Each process keeps its own buckets, so with N API workers or replicas a caller may reach N times
the configured rate; the limit is there to stop a runaway or stolen credential from flooding the
warehouse, not to meter fair use (a car needs ~2 requests/s). 0 disables a limit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass

# Bounds the memory a flood of distinct keys can take; the buckets simply start over when full.
MAX_BUCKETS = 100_000


@dataclass(slots=True)
class _Bucket:
    tokens: float
    updated_s: float


class RateLimiter:
    """`rate_per_s` requests per second sustained, up to `burst` at once, per key."""

    def __init__(
        self, rate_per_s: float, burst: float, *, clock: Callable[[], float] = time.monotonic
    ) -> None:
        if rate_per_s < 0 or burst < 1:
            raise ValueError("rate_per_s must be >= 0 and burst >= 1")
        self.rate_per_s = rate_per_s
        self.burst = float(burst)
        self._clock = clock
        self._buckets: dict[Hashable, _Bucket] = {}

    @property
    def enabled(self) -> bool:
        """False when configured with a rate of 0."""
        return self.rate_per_s > 0

    def wait_s(self, key: Hashable) -> float:
        """Take one request from the key's bucket: 0.0 if allowed, else seconds until it is."""
        if not self.enabled:
            return 0.0
        now = self._clock()
        bucket = self._buckets.get(key)
        if bucket is None:
            if len(self._buckets) >= MAX_BUCKETS:
                self._buckets.clear()
            bucket = self._buckets[key] = _Bucket(self.burst, now)
        else:
            bucket.tokens = min(
                self.burst, bucket.tokens + (now - bucket.updated_s) * self.rate_per_s
            )
            bucket.updated_s = now
        if bucket.tokens >= 1.0:
            bucket.tokens -= 1.0
            return 0.0
        return (1.0 - bucket.tokens) / self.rate_per_s


def retry_after_header(wait_s: float) -> dict[str, str]:
    """The Retry-After header for a refused request (whole seconds, at least 1)."""
    return {"Retry-After": str(max(1, math.ceil(wait_s)))}
