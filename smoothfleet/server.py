"""The server process's application: the API with the operators' dashboard mounted on it."""

from __future__ import annotations

import logging

from fastapi import FastAPI

from app.core.config import Settings
from app.main import create_api
from dashboards.site import install as install_dashboard

# The service's own packages, whose INFO lines (an assignment changed and by whom, a plan
# skipped) go to the process's standard error beside uvicorn's.
SERVICE_LOGGERS = ("app", "dashboards", "planner")


def log_service_lines() -> None:
    """Give the service's loggers a handler at INFO, once per process: uvicorn configures only
    its own, and Python drops INFO records of loggers without one. They still propagate, so a
    host's root handler (or a test's log capture) sees them too."""
    for name in SERVICE_LOGGERS:
        logger = logging.getLogger(name)
        if logger.handlers:
            continue
        handler = logging.StreamHandler()
        handler.setFormatter(logging.Formatter("%(levelname)s:     %(name)s: %(message)s"))
        logger.addHandler(handler)
        logger.setLevel(logging.INFO)


def create_app(settings: Settings | None = None) -> FastAPI:
    """The API for the database named in the settings, with the dashboard's pages."""
    log_service_lines()
    app = create_api(settings)
    install_dashboard(app)
    return app
