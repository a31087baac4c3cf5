"""`smoothfleet analytics`: the warehouse's analytics views (list, export as CSV)."""

from __future__ import annotations

import sys
from datetime import UTC, datetime
from pathlib import Path

import click
from rich.table import Table

from app.core.db import make_sync_engine
from smoothfleet.cli.common import (
    CliError,
    console,
    database,
    output_file,
    settings,
    write_output_with,
)


def _moment(value: str | None, option: str) -> datetime | None:
    """An ISO 8601 date or time from an option (UTC when it names no zone)."""
    if value is None:
        return None
    try:
        moment = datetime.fromisoformat(value)
    except ValueError:
        raise CliError(f"{option}: not an ISO 8601 date or time: {value!r}") from None
    moment = moment if moment.tzinfo is not None else moment.replace(tzinfo=UTC)
    try:
        moment.astimezone(UTC)
    except OverflowError:
        raise CliError(f"{option}: {value!r} is out of range once read in UTC") from None
    return moment


@click.group("analytics")
def analytics_group() -> None:
    """The analytics views (schema `analytics`, docs/analytics.md)."""


@analytics_group.command("list")
def analytics_list() -> None:
    """Name the views and what one row of each is."""
    from app.analytics import VIEWS

    table = Table("view", "one row per", "time column")
    for view in VIEWS.values():
        table.add_row(view.name, view.grain, view.time_column)
    console.print(table)


@analytics_group.command("export")
@click.argument("view_name")
@click.option("--since", help="From this ISO 8601 date or time (UTC unless a zone is given).")
@click.option("--until", help="Up to (not including) this date or time.")
@click.option("--vehicle", "vehicle_id", help="Only this vehicle (views with a vehicle_id).")
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, allow_dash=True),
    default="-",
    show_default=True,
    help="CSV file to write (- for standard output).",
)
def analytics_export(
    view_name: str, since: str | None, until: str | None, vehicle_id: str | None, output: str
) -> None:
    """Export one analytics view as CSV (header row, ISO 8601 times in UTC).

    The rows are read before the file is written, and the file is replaced only when it is
    whole: a refused request or a failed query leaves an earlier export as it was."""
    from app.analytics import ViewRequestError, export_csv, read_view, view_query

    window = {"since": _moment(since, "--since"), "until": _moment(until, "--until")}
    try:  # every mistake in the request named before the database starts
        view_query(view_name, vehicle_id=vehicle_id, **window)
    except ViewRequestError as error:
        raise CliError(f"analytics export: {error}") from None
    if output != "-":
        output_file(Path(output), "--output")
    with database(settings()) as url, make_sync_engine(url).connect() as connection:
        try:
            frame = read_view(connection, view_name, vehicle_id=vehicle_id, **window)
        except ViewRequestError as error:
            raise CliError(f"analytics export: {error}") from None
    if output == "-":
        rows = export_csv(frame, sys.stdout)
    else:

        def write(path: Path) -> None:
            with path.open("w", encoding="utf-8", newline="") as out:
                export_csv(frame, out)

        write_output_with(Path(output), write)
        rows = len(frame)
    click.echo(f"{rows} row(s) of analytics.{view_name}", err=True)
