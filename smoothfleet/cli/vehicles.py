"""`smoothfleet vehicles`: the fleet roster (list, add, import a CSV)."""

from __future__ import annotations

from pathlib import Path

import click
from pydantic import ValidationError
from rich.table import Table
from sqlalchemy.exc import IntegrityError

from app.core.db import make_sync_engine, session_scope
from app.vehicles.schemas import RosterRow
from app.vehicles.service import list_vehicles, parse_roster_csv, upsert_vehicles
from contract.values import first_problem
from smoothfleet.cli.common import CliError, console, database, settings


@click.group()
def vehicles() -> None:
    """The fleet roster."""


@vehicles.command("list")
def vehicles_list() -> None:
    """Show the roster."""
    with database(settings()) as url, session_scope(make_sync_engine(url)) as session:
        rows = list(list_vehicles(session))
        table = Table(
            "vehicle", "make", "model", "year", "actuation", "route", "lane", "controller", "active"
        )
        for vehicle in rows:
            table.add_row(
                vehicle.vehicle_id,
                vehicle.make,
                vehicle.model,
                str(vehicle.year),
                vehicle.actuation,
                vehicle.route,
                str(vehicle.assigned_lane),
                vehicle.controller_name,
                "maintenance" if vehicle.is_in_maintenance else str(vehicle.is_active).lower(),
            )
    console.print(table)
    console.print(f"{len(rows)} vehicle(s)")


@vehicles.command("add")
@click.option("--id", "vehicle_id", required=True, help="Roster id, e.g. SF-101.")
@click.option("--vin", required=True)
@click.option("--make", required=True)
@click.option("--model", required=True)
@click.option("--year", required=True, type=int)
@click.option("--actuation", required=True, type=click.Choice(["acc", "accel"]))
@click.option("--corridor", "corridor_id", default="I-24-WB", show_default=True)
@click.option("--route", required=True)
@click.option("--lane", "assigned_lane", required=True, type=int)
@click.option("--controller", "controller_name", required=True)
@click.option("--params", "controller_params", default="{}", help="Controller params as JSON.")
def vehicles_add(**fields: object) -> None:
    """Add one vehicle (or update it if the id exists)."""
    try:
        row = RosterRow.model_validate(fields)
    except ValidationError as error:
        raise CliError(f"vehicle: {first_problem(error)}") from None
    with database(settings()) as url:
        _write_roster(url, [row], label=None)
    console.print(f"vehicle {row.vehicle_id} saved")


@vehicles.command("import")
@click.argument("csv_file", type=click.Path(path_type=Path))
def vehicles_import(csv_file: Path) -> None:
    """Import a roster CSV (columns as seed_data/roster.csv) in one transaction."""
    rows = parse_roster_csv(csv_file)
    with database(settings()) as url:
        written = _write_roster(url, rows, label=csv_file.name)
    console.print(f"imported {written} vehicle(s) from {csv_file}")


def _write_roster(url: str, rows: list[RosterRow], *, label: str | None) -> int:
    try:
        with session_scope(make_sync_engine(url)) as session:
            return upsert_vehicles(session, rows, update_existing=True, label=label)
    except IntegrityError as error:
        diag = getattr(error.orig, "diag", None)
        reason = (diag.message_detail or diag.message_primary) if diag else None
        source = label if label is not None else f"vehicle {rows[0].vehicle_id}"
        raise CliError(f"{source}: refused by the database: {reason or error.orig}") from None
