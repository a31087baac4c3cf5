"""`smoothfleet serve`: the API, the dashboard and the planner schedule."""

from __future__ import annotations

import errno
import os
import shutil
import socket
import tempfile

import click

from app.core.config import Settings, get_settings
from app.core.db import make_sync_engine
from app.core.metrics import MULTIPROCESS_DIR_ENV
from smoothfleet.cli.common import CliError, database, settings


def ensure_port_free(host: str, port: int) -> None:
    """Fail with one line if the port is taken, before any server starts."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((host, port))
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                raise CliError(
                    f"port {port} on {host} is already in use (choose another with --port "
                    "or SMOOTHFLEET_PORT)"
                ) from None
            raise CliError(f"cannot listen on {host}:{port}: {error.strerror}") from None


WORKER_STARTUP_TIMEOUT_S = 120


def run_server(url: str, current: Settings, *, migrate: bool) -> None:
    """Migrate (under a lock, so replicas do it once) and run uvicorn until stopped."""
    import uvicorn

    from app.migrate import upgrade

    if migrate:
        upgrade(make_sync_engine(url))
    # Workers are separate processes: they read the resolved URL from the environment.
    os.environ["SMOOTHFLEET_DATABASE_URL"] = url
    get_settings.cache_clear()
    metrics_dir = None
    if current.workers > 1 and not os.environ.get(MULTIPROCESS_DIR_ENV):
        # /metrics sums every worker's counters through this directory (app/core/metrics.py).
        metrics_dir = tempfile.mkdtemp(prefix="smoothfleet-metrics-")
        os.environ[MULTIPROCESS_DIR_ENV] = metrics_dir
    try:
        uvicorn.run(
            "smoothfleet.server:create_app",
            factory=True,
            host=current.host,
            port=current.port,
            workers=current.workers,
            log_level="info",
            access_log=False,
            # Forwarded-for headers are the app's to believe, from SMOOTHFLEET_TRUSTED_PROXIES
            # only (uvicorn's own default trusts any peer on 127.0.0.1).
            proxy_headers=False,
            # A worker imports the whole app (pandas, the dashboard) before it answers the
            # supervisor; uvicorn's 5 s default restarts it forever on a loaded small machine.
            timeout_worker_healthcheck=WORKER_STARTUP_TIMEOUT_S,
        )
    finally:
        if metrics_dir is not None:
            shutil.rmtree(metrics_dir, ignore_errors=True)


@click.command("serve")
@click.option("--host", help="Listen address (SMOOTHFLEET_HOST).")
@click.option("--port", type=int, help="Listen port (SMOOTHFLEET_PORT).")
@click.option("--workers", type=int, help="uvicorn worker processes (SMOOTHFLEET_WORKERS).")
@click.option("--no-migrate", is_flag=True, help="Do not run migrations before serving.")
@click.option("--no-planner", is_flag=True, help="Do not run the planner schedule in this server.")
def serve(
    host: str | None, port: int | None, workers: int | None, no_migrate: bool, no_planner: bool
) -> None:
    """Run the API and dashboard (and the planner schedule unless --no-planner)."""
    if no_planner:
        # The workers read their settings from the environment.
        os.environ["SMOOTHFLEET_PLANNER_ENABLED"] = "false"
        get_settings.cache_clear()
    current = with_overrides(host=host, port=port, workers=workers)
    ensure_port_free(current.host, current.port)
    with database(current) as url:
        run_server(url, current, migrate=not no_migrate)


def with_overrides(**overrides: object) -> Settings:
    from app.core.config import load_settings

    given = {name: value for name, value in overrides.items() if value is not None}
    if not given:
        return settings()
    return load_settings(**given)
