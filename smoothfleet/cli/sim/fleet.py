"""`smoothfleet sim fleet`: a simulated fleet and INRIX feed against a running server."""

from __future__ import annotations

import click
import httpx

from contract.values import http_url
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

    server_url = server_url.rstrip("/")
    check_server(server_url)
    current = settings()
    with database(current) as url:
        try:
            summary = run_fleet(
                url,
                current,
                server_url,
                run_dir=new_run_dir(current),
                duration_s=duration,
                vehicles=vehicles,
                say=console.print,
            )
        except DemoError as error:
            raise CliError(f"sim fleet: {error}") from None
    for line in summary.lines():
        console.print(line)


def check_server(server_url: str) -> None:
    """A BadParameter naming what is wrong with `--server` before any car starts: it was
    taken as given, the workers retried for about 20 s, and the command said only that a
    worker exited."""
    try:
        http_url(server_url)  # the check every setting naming a server passes
    except ValueError as error:
        raise click.BadParameter(
            f"{server_url!r}: {error}, e.g. http://api:8000", param_hint="--server"
        ) from None
    try:
        answer = httpx.get(f"{server_url}/healthz", timeout=5.0)
    except httpx.HTTPError as error:
        raise click.BadParameter(
            f"no smoothfleet API answers at {server_url} ({type(error).__name__}: {error})",
            param_hint="--server",
        ) from None
    if answer.status_code != 200:
        raise click.BadParameter(
            f"{server_url}/healthz answered HTTP {answer.status_code}: is it a smoothfleet API?",
            param_hint="--server",
        )
