"""Repeated identical log lines are written once per window, with how often they recurred.

During a database outage every request meets the same error; a line per request (hundreds a
second) buries everything else in the log. A logger given `RepeatedMessages` writes the first
occurrence of a message, drops identical ones for `window_s`, and the next occurrence after the
window carries the count of those dropped.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable


class RepeatedMessages(logging.Filter):
    """Let one of identical records through per window; count the others."""

    def __init__(
        self, window_s: float = 10.0, *, clock: Callable[[], float] = time.monotonic
    ) -> None:
        super().__init__()
        self._window_s = window_s
        self._clock = clock
        self._lock = threading.Lock()
        # message key -> (when it was last written, how many were dropped since)
        self._seen: dict[tuple[str, int, str], tuple[float, int]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        """False for a repeat inside the window; otherwise True, the count appended."""
        key = (record.name, record.levelno, record.getMessage())
        now = self._clock()
        with self._lock:
            written_at, dropped = self._seen.get(key, (-float("inf"), 0))
            if now - written_at < self._window_s:
                self._seen[key] = (written_at, dropped + 1)
                return False
            self._seen[key] = (now, 0)
            if len(self._seen) > 1000:  # forget the oldest keys; a log is not a database
                for stale in sorted(self._seen, key=lambda k: self._seen[k][0])[:500]:
                    del self._seen[stale]
        if dropped:
            record.msg = f"{record.getMessage()} (repeated {dropped} times since last shown)"
            record.args = None
        return True
