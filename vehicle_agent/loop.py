"""Keeping the control period: a rate keeper that sleeps to each deadline and measures lag."""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable

import numpy as np


class RateKeeper:
    """Wake every `period_s`; `wait()` returns how late this wake-up is (the lag)."""

    def __init__(
        self,
        period_s: float,
        clock: Callable[[], float] = time.monotonic,
        sleep: Callable[[float], None] = time.sleep,
        window: int = 1000,
    ) -> None:
        self.period_s = period_s
        self.clock = clock
        self.sleep = sleep
        self.next_deadline = clock() + period_s
        self.lags: deque[float] = deque(maxlen=window)
        self.missed = 0

    def wait(self) -> float:
        """Sleep until the next deadline; a deadline already missed by a whole period is skipped
        (counted in `missed`) instead of running a burst of late steps."""
        remaining = self.next_deadline - self.clock()
        if remaining > 0:
            self.sleep(remaining)
        now = self.clock()
        lag = max(now - self.next_deadline, 0.0)
        self.lags.append(lag)
        self.next_deadline += self.period_s
        if now - self.next_deadline > self.period_s:
            skipped = int((now - self.next_deadline) // self.period_s) + 1
            self.missed += skipped
            self.next_deadline += skipped * self.period_s
        return lag

    def lag_percentile(self, percent: float) -> float:
        """A percentile (0-100) of the recent lags (s)."""
        return float(np.percentile(list(self.lags), percent)) if self.lags else 0.0
