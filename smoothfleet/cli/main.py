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

from smoothfleet.cli.common import CliError, CommandGroup, LazyCommand

# Every command is imported only when a command line names it: their imports (SQLAlchemy and
# the models, pandas, matplotlib, the simulator) were most of the start-up time of each. The
# summaries are the first lines of the commands' own help (tests/smoothfleet/test_startup.py).
COMMANDS = {
    "analytics": LazyCommand(
        "smoothfleet.cli.analytics:analytics_group",
        "The analytics views (schema `analytics`, docs/analytics.md).",
    ),
    "db": LazyCommand(
        "smoothfleet.cli.db:db", "The warehouse database: migrations, URL, psql, housekeeping."
    ),
    "demo": LazyCommand(
        "smoothfleet.cli.demo:demo",
        "Everything on one machine: embedded database, migrations, seed, API, dashboard, "
        "planner, a simulated INRIX feed and a simulated fleet whose cars run the real vehicle "
        "agent.",
    ),
    "inrix": LazyCommand(
        "smoothfleet.cli.inrix:inrix",
        "The INRIX segment-speed feed: poll the provider, replay or convert recordings.",
    ),
    "motion": LazyCommand(
        "smoothfleet.cli.motion:motion",
        "I-24 MOTION trajectories: import, Edie fields, the bulk-fuel figure.",
    ),
    "planner": LazyCommand(
        "smoothfleet.cli.planner:planner",
        "The Speed Planner: its schedule, a single cycle, and replay of a stored plan.",
    ),
    "policy": LazyCommand(
        "smoothfleet.cli.policy:policy",
        "Trained controller policies stored on the server by sha256.",
    ),
    "seed": LazyCommand(
        "smoothfleet.cli.db:seed_command",
        "Load the I-24-WB corridor, its segments and the 100-car roster (idempotent).",
    ),
    "serve": LazyCommand(
        "smoothfleet.cli.serve:serve",
        "Run the API and dashboard (and the planner schedule unless --no-planner).",
    ),
    "sim": LazyCommand(
        "smoothfleet.cli.sim:sim",
        "Simulate platoons on real I-24 drives: evaluate planners x controllers.",
    ),
    "tokens": LazyCommand("smoothfleet.cli.tokens:tokens", "API bearer tokens."),
    "users": LazyCommand(
        "smoothfleet.cli.users:users", "Dashboard users (roles viewer, operator, admin)."
    ),
    "vehicles": LazyCommand("smoothfleet.cli.vehicles:vehicles", "The fleet roster."),
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

    Its types are imported here, once a command has failed, not at start-up: a command that
    never touches the database (`sim`, `motion generate`) starts without SQLAlchemy, and one
    that does has them loaded already (an error is raised only by a module that was
    imported)."""
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
