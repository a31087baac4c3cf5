"""Logging that cannot flood a car's disk: repeated problems are logged once per interval."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable


class ThrottledLog:
    """Log a problem of one kind at most once per `interval_s`, with how many were suppressed."""

    def __init__(
        self,
        logger: logging.Logger,
        interval_s: float = 10.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.logger = logger
        self.interval_s = interval_s
        self.clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}

    def warning(self, kind: str, message: str) -> None:
        """Log `message` unless a `kind` problem was logged within the interval."""
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval_s:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return
        suppressed = self._suppressed.pop(kind, 0)
        suffix = f" ({suppressed} more like it suppressed)" if suppressed else ""
        self.logger.warning("%s%s", message, suffix)
        self._last[kind] = now
