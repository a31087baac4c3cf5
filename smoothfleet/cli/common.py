"""What every `smoothfleet` command group shares: the database it works on, its settings, its
console, and the one-line failure it may end with."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from rich.console import Console

from app.core.config import Settings, get_settings
from app.core.db import check_reachable

console = Console()


class CliError(Exception):
    """An expected failure: its message is printed as one line and the exit code is 1."""


@contextmanager
def database(settings: Settings) -> Iterator[str]:
    """The URL of the database to use, starting the embedded server if none is configured."""
    if settings.database_url is not None:
        check_reachable(settings.database_url, settings.db_connect_timeout_s)
        yield settings.database_url
        return
    from app.core.embedded import embedded_postgres

    with embedded_postgres(settings.data_dir) as url:
        yield url


def settings() -> Settings:
    """The settings of this invocation."""
    return get_settings()
