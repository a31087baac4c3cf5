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
        suffix = self._due(kind)
        if suffix is not None:
            self.logger.warning("%s%s", message, suffix)

    def exception(self, kind: str, message: str) -> None:
        """`warning` at ERROR with the traceback of the exception being handled: a step that
        fails at its loop's rate (the CAN interface gone) wrote 30 tracebacks a second."""
        suffix = self._due(kind)
        if suffix is not None:
            self.logger.exception("%s%s", message, suffix)

    def _due(self, kind: str) -> str | None:
        """The suffix to log a `kind` problem with now, or None while its interval runs."""
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval_s:
            self._suppressed[kind] = self._suppressed.get(kind, 0) + 1
            return None
        suppressed = self._suppressed.pop(kind, 0)
        self._last[kind] = now
        return f" ({suppressed} more like it suppressed)" if suppressed else ""
