"""`smoothfleet`: the server-side command line (see docs/interfaces.md, "Command line").

Every command that needs the database gets it from `database()`: the server named by
SMOOTHFLEET_DATABASE_URL, or else the embedded PostgreSQL under SMOOTHFLEET_DATA_DIR, started
for the command and stopped when the last process using it exits. Expected failures (a bad
setting, an unreachable server, a bad CSV row, a taken port) end with one line on stderr and a
non-zero exit code, never a traceback.
"""

from __future__ import annotations

import os
import signal
from types import FrameType
from typing import NoReturn

import click

from smoothfleet.cli.common import CliError, CommandGroup

# Every command is imported only when a command line names it: their imports (SQLAlchemy and
# the models, pandas, matplotlib, the simulator) were most of the start-up time of each.
COMMANDS = {
    "db": "smoothfleet.cli.db:db",
    "seed": "smoothfleet.cli.db:seed_command",
    "vehicles": "smoothfleet.cli.vehicles:vehicles",
    "tokens": "smoothfleet.cli.tokens:tokens",
    "users": "smoothfleet.cli.users:users",
    "analytics": "smoothfleet.cli.analytics:analytics_group",
    "serve": "smoothfleet.cli.serve:serve",
    "demo": "smoothfleet.cli.demo:demo",
    **{
        name: f"smoothfleet.cli.{name}:{name}"
        for name in ("inrix", "sim", "planner", "motion", "policy")
    },
}


@click.group(
    cls=CommandGroup,
    lazy=COMMANDS,
    context_settings={"help_option_names": ["-h", "--help"]},
)
def cli() -> None:
    """smoothfleet: run a fleet of traffic-smoothing vehicles (server side)."""


# --- entry point ---------------------------------------------------------------------------


def _exit_on_sigterm(signum: int, frame: FrameType | None) -> NoReturn:
    """SIGTERM unwinds like Ctrl-C, so the embedded database is stopped on the way out.

    Further SIGTERMs and Ctrl-Cs are ignored from here on: the clean-up must not be cut short.
    """
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise SystemExit(128 + signum)


def fail(message: str) -> NoReturn:
    """Print one line and exit non-zero."""
    click.echo(f"smoothfleet: error: {message}", err=True)
    raise SystemExit(1)


def main() -> None:
    """Console-script entry point."""
    signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        cli(standalone_mode=False)
    except click.exceptions.Abort:
        raise SystemExit(130) from None
    except click.ClickException as error:
        error.show()
        raise SystemExit(error.exit_code) from None
    except CliError as error:
        fail(str(error))
    except KeyboardInterrupt:
        raise SystemExit(130) from None
    except SystemExit:
        raise
    except Exception as error:
        expected = expected_failure(error)
        if expected is not None:
            fail(expected)
        if os.environ.get("SMOOTHFLEET_DEBUG"):  # a bug: still one line, details on request
            raise
        fail(f"unexpected {type(error).__name__}: {error} (set SMOOTHFLEET_DEBUG=1 for details)")


def expected_failure(error: Exception) -> str | None:
    """The one line an expected failure of the server side ends with (None: a bug).

    Its types are imported here, not at start-up: an error can only come from a module the
    failing command imported, so they cost that command nothing, and a command that never
    touches the database (`sim`, `motion generate`) starts without SQLAlchemy."""
    from psycopg.errors import UndefinedTable
    from sqlalchemy.exc import ProgrammingError

    from app.core.config import SettingsError
    from app.core.db import DatabaseUnavailable
    from app.vehicles.service import RosterError

    if isinstance(error, SettingsError | DatabaseUnavailable | RosterError):
        return str(error)
    if isinstance(error, ProgrammingError) and isinstance(error.orig, UndefinedTable):
        return "the database has no smoothfleet schema yet: run `smoothfleet db upgrade`"
    return None
