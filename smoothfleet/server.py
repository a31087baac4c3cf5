"""The server process's application: the API with the operators' dashboard mounted on it."""

from __future__ import annotations

from fastapi import FastAPI

from app.core.config import Settings
from app.main import create_api
from dashboards.site import install as install_dashboard


def create_app(settings: Settings | None = None) -> FastAPI:
    """The API for the database named in the settings, with the dashboard's pages."""
    app = create_api(settings)
    install_dashboard(app)
    return app
