"""`smoothfleet tokens`: the API's bearer tokens (create, revoke, list)."""

from __future__ import annotations

import sys

import click
from rich.table import Table
from sqlalchemy.exc import IntegrityError

from app.core.db import make_sync_engine, session_scope
from app.core.security import TOKEN_ROLES, issue_token
from smoothfleet.cli.common import (
    BIGINT_ID,
    CliError,
    console,
    database,
    settings,
    storable_text_option,
)


@click.group()
def tokens() -> None:
    """API bearer tokens."""


@tokens.command("create")
@click.option("--role", required=True, type=click.Choice(TOKEN_ROLES))
@click.option(
    "--vehicle",
    "vehicle_id",
    callback=storable_text_option,
    help="The vehicle a vehicle token is bound to.",
)
@click.option(
    "--name", default="", callback=storable_text_option, help="A note on who holds the token."
)
def tokens_create(role: str, vehicle_id: str | None, name: str) -> None:
    """Issue a token and print it once (only its hash is stored)."""
    if (role == "vehicle") != (vehicle_id is not None):
        raise CliError("tokens create: --vehicle is required for --role vehicle, and only there")
    with database(settings()) as url:
        try:
            with session_scope(make_sync_engine(url)) as session:
                token = issue_token(session, role, vehicle_id=vehicle_id, name=name)  # type: ignore[arg-type]
        except IntegrityError:
            raise CliError(f"tokens create: unknown vehicle {vehicle_id}") from None
    click.echo(token)


@tokens.command("revoke")
@click.option("--id", "token_id", type=BIGINT_ID, help="The token's id (see `tokens list`).")
@click.option(
    "--vehicle",
    "vehicle_id",
    callback=storable_text_option,
    help="Revoke every live token of this vehicle.",
)
@click.option(
    "--token-stdin", is_flag=True, help="Read the token itself from standard input (one line)."
)
def tokens_revoke(token_id: int | None, vehicle_id: str | None, token_stdin: bool) -> None:
    """Revoke tokens; servers refuse them within SMOOTHFLEET_TOKEN_CACHE_TTL_S seconds."""
    from app.core.security import revoke_tokens

    token = sys.stdin.readline().strip() if token_stdin else None
    if sum(value is not None for value in (token_id, vehicle_id, token)) != 1:
        raise CliError("tokens revoke: give exactly one of --id, --vehicle, --token-stdin")
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        revoked = revoke_tokens(session, token_id=token_id, vehicle_id=vehicle_id, token=token)
    if not revoked:
        raise CliError("tokens revoke: no live token matches")
    console.print(f"revoked token(s) {', '.join(str(number) for number in revoked)}")


@tokens.command("list")
def tokens_list() -> None:
    """Show issued tokens (never the tokens themselves: only their hashes are stored)."""
    from app.core.security import list_tokens

    table = Table("id", "kind", "role", "vehicle", "name", "created", "last used", "revoked")
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        for row in list_tokens(session):
            table.add_row(
                str(row.token_id),
                row.kind,
                row.role or "",
                row.vehicle_id or "",
                row.name,
                f"{row.created_at:%Y-%m-%d %H:%M}",
                f"{row.last_used_at:%Y-%m-%d %H:%M}" if row.last_used_at else "",
                f"{row.revoked_at:%Y-%m-%d %H:%M}" if row.revoked_at else "",
            )
    console.print(table)
