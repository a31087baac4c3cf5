"""Repeated identical log lines: the first is written, repeats inside the window are counted."""

from __future__ import annotations

import logging

import pytest

from app.core.logs import RepeatedMessages


def test_identical_lines_are_written_once_per_window_with_the_count(
    caplog: pytest.LogCaptureFixture,
) -> None:
    now = [0.0]
    log = logging.getLogger("tests.repeated")
    repeats = RepeatedMessages(window_s=10.0, clock=lambda: now[0])
    log.addFilter(repeats)
    try:
        with caplog.at_level(logging.WARNING, logger="tests.repeated"):
            for second in range(25):  # one line a second, for 25 s
                now[0] = float(second)
                log.warning("database unavailable: %s", "connection refused")
            log.warning("another message")
    finally:
        log.removeFilter(repeats)

    assert [record.getMessage() for record in caplog.records] == [
        "database unavailable: connection refused",
        "database unavailable: connection refused (repeated 9 times since last shown)",
        "database unavailable: connection refused (repeated 9 times since last shown)",
        "another message",
    ]
