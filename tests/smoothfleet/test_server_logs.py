"""The server process writes the service's own INFO lines, not only uvicorn's."""

from __future__ import annotations

import logging

import pytest

from smoothfleet.server import SERVICE_LOGGERS, log_service_lines


def test_the_services_info_lines_reach_standard_error(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """An assignment's 'changed by' line was logged at INFO to a logger with no handler, and
    so written nowhere: the demo's server.log held uvicorn's lines only."""
    for name in SERVICE_LOGGERS:  # as a fresh process has them, restored after
        logger = logging.getLogger(name)
        monkeypatch.setattr(logger, "handlers", [])
        monkeypatch.setattr(logger, "level", logging.NOTSET)
    log_service_lines()
    log_service_lines()  # once per process, however many apps it creates

    logging.getLogger("app.fleet.service").info("assignment of SF-001 changed by operator")

    assert capsys.readouterr().err == (
        "INFO:     app.fleet.service: assignment of SF-001 changed by operator\n"
    )
