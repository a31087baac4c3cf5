"""`smoothfleet sim fleet`: a simulated fleet and INRIX feed against a running server."""

from __future__ import annotations

import click

from smoothfleet.cli.common import fleet_options
from smoothfleet.cli.sim.shared import console


@click.command("fleet")
@click.option(
    "--server",
    "server_url",
    required=True,
    help="Base URL of a running smoothfleet API, e.g. http://api:8000.",
)
@fleet_options
def fleet_command(server_url: str, duration: float | None, vehicles: int) -> None:
    """A simulated fleet and INRIX feed against a running server (docker compose `fleet`).

    Every car runs the real vehicle agent on its own virtual CAN bus with a car emulator and
    its own token, issued in the database the server uses (SMOOTHFLEET_DATABASE_URL).
    """
    from smoothfleet.cli.common import CliError, database, settings
    from smoothfleet.cli.demo import DemoError, new_run_dir, run_fleet

    current = settings()
    with database(current) as url:
        try:
            summary = run_fleet(
                url,
                current,
                server_url.rstrip("/"),
                run_dir=new_run_dir(current),
                duration_s=duration,
                vehicles=vehicles,
                say=console.print,
            )
        except DemoError as error:
            raise CliError(f"sim fleet: {error}") from None
    for line in summary.lines():
        console.print(line)
