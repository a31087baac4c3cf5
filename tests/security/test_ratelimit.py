"""The token bucket, worked by hand on a manual clock."""

from __future__ import annotations

import pytest

from app.core.ratelimit import RateLimiter, retry_after_header


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_burst_then_the_sustained_rate() -> None:
    clock = Clock()
    limiter = RateLimiter(rate_per_s=2.0, burst=3, clock=clock)
    assert [limiter.wait_s("car") for _ in range(3)] == [0.0, 0.0, 0.0]
    # Bucket empty: the next token arrives after 1 / 2 s.
    assert limiter.wait_s("car") == pytest.approx(0.5)
    clock.now += 0.25  # half a token refilled
    assert limiter.wait_s("car") == pytest.approx(0.25)
    clock.now += 0.25
    assert limiter.wait_s("car") == 0.0
    # Another key has its own bucket.
    assert limiter.wait_s("other") == 0.0


def test_refill_never_exceeds_the_burst() -> None:
    clock = Clock()
    limiter = RateLimiter(rate_per_s=10.0, burst=2, clock=clock)
    limiter.wait_s("car")
    clock.now += 3600
    assert [limiter.wait_s("car") for _ in range(3)] == [0.0, 0.0, pytest.approx(0.1)]


def test_a_rate_of_zero_disables_the_limit() -> None:
    limiter = RateLimiter(rate_per_s=0.0, burst=1)
    assert not limiter.enabled
    assert all(limiter.wait_s("car") == 0.0 for _ in range(1000))


def test_retry_after_rounds_up_to_whole_seconds() -> None:
    assert retry_after_header(0.01) == {"Retry-After": "1"}
    assert retry_after_header(2.2) == {"Retry-After": "3"}
