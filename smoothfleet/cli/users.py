"""`smoothfleet users`: the dashboard's logins (add or reset, list)."""

from __future__ import annotations

import sys

import click
from rich.table import Table

from app.core.db import make_sync_engine, session_scope
from app.users.service import (
    OPS_ROLES,
    UserError,
    check_new_user,
    list_login_failures,
    list_users,
    save_user,
)
from smoothfleet.cli.common import CliError, console, database, settings


@click.group()
def users() -> None:
    """Dashboard users (roles viewer, operator, admin)."""


@users.command("add")
@click.argument("username")
@click.option("--role", required=True, type=click.Choice(OPS_ROLES))
@click.option(
    "--password-stdin", is_flag=True, help="Read the password from standard input (one line)."
)
def users_add(username: str, role: str, password_stdin: bool) -> None:
    """Create a dashboard user, or reset an existing user's role and password."""
    if password_stdin:
        password = sys.stdin.readline().rstrip("\r\n")
    elif not sys.stdin.isatty():
        # click's prompt read end-of-input and left with exit 130 and no word (compose's
        # `run -T`, a script)
        raise CliError(
            "users add: no terminal to ask the password on: pipe it in with --password-stdin"
        )
    else:
        password = click.prompt("password", hide_input=True, confirmation_prompt=True)
    try:
        check_new_user(username, role, password)
    except UserError as error:
        raise CliError(f"users add: {error}") from None
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        created = save_user(session, username, role, password)
    console.print(f"user {username} {'created' if created else 'updated'} with role {role}")


@users.command("list")
def users_list() -> None:
    """Show the dashboard users, and the clients whose failed logins make them wait: each by
    the key the wait counts (an IPv4 address or an IPv6 /64), so the list says who waits."""
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        table = Table("user", "role", "last login", "failed logins", "last failed")
        for user in list_users(session):
            last = user.last_login_at.isoformat(timespec="seconds") if user.last_login_at else ""
            failed = (
                user.last_failed_at.isoformat(timespec="seconds") if user.last_failed_at else ""
            )
            table.add_row(user.username, user.role, last, str(user.failed_logins), failed)
        clients = Table("user", "client (IPv4 address or IPv6 /64)", "failures", "last failed")
        for failure in list_login_failures(session):
            clients.add_row(
                failure.username,
                failure.client_address,
                str(failure.failures),
                failure.last_failed_at.isoformat(timespec="seconds"),
            )
    console.print(table)
    if clients.row_count:
        console.print(clients)
