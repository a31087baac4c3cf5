"""Roster operations: list, add, import from CSV (one transaction, all rows or none)."""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, TextIO

from pydantic import ValidationError
from sqlalchemy import case, select, tuple_
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.orm import Session

from app.models import Corridor, Policy, Vehicle, VehicleChange
from app.vehicles.schemas import RosterRow
from contract.controllers import RL_CONTROLLERS
from contract.values import first_problem


class RosterError(ValueError):
    """A roster row is wrong; the message names the row and the field."""


def parse_roster_csv(path: Path) -> list[RosterRow]:
    """Read and validate a roster CSV; raise RosterError naming the first bad row (1 = header)."""
    try:
        handle = path.open(newline="", encoding="utf-8-sig")
    except OSError as error:
        raise RosterError(f"{path}: {error.strerror}") from None
    try:
        with handle:
            return _roster_rows(path, handle)
    except UnicodeDecodeError as error:
        raise RosterError(
            f"{path.name}: not UTF-8 text ({error.reason}); save the roster as CSV UTF-8"
        ) from None


def _roster_rows(path: Path, handle: TextIO) -> list[RosterRow]:
    """The rows of an open roster CSV, validated (`parse_roster_csv`)."""
    reader = csv.DictReader(handle)
    expected = set(RosterRow.model_fields)
    header = set(reader.fieldnames or ())
    missing = sorted(expected - header - {"controller_params"})
    if missing:
        raise RosterError(f"{path.name} row 1: missing column(s) {', '.join(missing)}")
    unknown = sorted(header - expected)
    if unknown:
        raise RosterError(f"{path.name} row 1: unknown column(s) {', '.join(unknown)}")
    rows = []
    for number, record in enumerate(reader, start=2):
        # the record's number, and the file's line it ends on where they differ (blank lines
        # skipped, a quoted field over several lines): an editor shows lines
        where = f"row {number}" + (
            f" (line {reader.line_num})" if reader.line_num != number else ""
        )
        if None in record:
            raise RosterError(f"{path.name} {where}: more fields than the header")
        try:
            rows.append(RosterRow.model_validate(record))
        except ValidationError as error:
            raise RosterError(f"{path.name} {where}: {first_problem(error)}") from None
    return rows


def _where(label: str | None, number: int, row: RosterRow) -> str:
    """Where a row came from, in an error: a file's row, or the vehicle given on its own
    (`label` None: `vehicles add`, which has no rows to number)."""
    return f"vehicle {row.vehicle_id}" if label is None else f"{label} row {number}"


def _check_against_corridors(
    session: Session, rows: Sequence[RosterRow], label: str | None
) -> None:
    rows_found = session.execute(select(Corridor.corridor_id, Corridor.lanes)).all()
    lanes = {row[0]: row[1] for row in rows_found}
    seen_ids: set[str] = set()
    seen_vins: set[str] = set()
    for number, row in enumerate(rows, start=2):
        where = _where(label, number, row)
        if row.corridor_id not in lanes:
            raise RosterError(f"{where}: corridor_id {row.corridor_id!r} is not a known corridor")
        if row.assigned_lane > lanes[row.corridor_id]:
            raise RosterError(
                f"{where}: assigned_lane {row.assigned_lane} is beyond the "
                f"{lanes[row.corridor_id]} lanes of {row.corridor_id}"
            )
        if row.vehicle_id in seen_ids:
            raise RosterError(f"{where}: vehicle_id {row.vehicle_id} appears twice")
        if row.vin in seen_vins:
            raise RosterError(f"{where}: vin {row.vin} appears twice")
        seen_ids.add(row.vehicle_id)
        seen_vins.add(row.vin)
    _check_policies_held(session, rows, label)


def _check_policies_held(session: Session, rows: Sequence[RosterRow], label: str | None) -> None:
    """A row naming a policy by sha256 needs that policy on the server, for its controller
    (the car downloads it from here), as an assignment does."""
    named = {
        str(row.controller_params["policy_sha256"])
        for row in rows
        if row.controller_name in RL_CONTROLLERS and "policy_sha256" in row.controller_params
    }
    if not named:
        return
    held = dict(
        session.execute(
            select(Policy.policy_sha256, Policy.controller).where(Policy.policy_sha256.in_(named))
        ).all()
    )
    for number, row in enumerate(rows, start=2):
        sha256 = row.controller_params.get("policy_sha256")
        if row.controller_name not in RL_CONTROLLERS or sha256 is None:
            continue
        where = f"{_where(label, number, row)}: controller_params.policy_sha256"
        if sha256 not in held:
            raise RosterError(f"{where}: no policy {sha256} on the server (upload it first)")
        if held[sha256] != row.controller_name:
            raise RosterError(f"{where}: a {held[sha256]} policy, not {row.controller_name}")


def upsert_vehicles(
    session: Session,
    rows: Sequence[RosterRow],
    *,
    update_existing: bool,
    label: str | None = "roster",
) -> int:
    """Write the rows; existing vehicles are updated or left alone. Returns rows written.
    `label` names where the rows came from in an error and in the change rows (None: vehicles
    given one by one).

    An existing vehicle the rows change gets a new config version and, as an assignment
    through the API does, a fact_vehicle_change row saying who made it and what it set. (A
    change made in SQL, such as `is_active`, gets its new version from migration 0022's trigger
    and no row: the one kind of version the history does not explain.)"""
    _check_against_corridors(session, rows, label)
    if not rows:
        return 0
    names = [name for name in RosterRow.model_fields if name != "vehicle_id"]
    # Locked until the commit: the versions and fields compared below are the ones this load
    # replaces.
    stored = session.execute(
        select(Vehicle.vehicle_id, Vehicle.config_version, *(getattr(Vehicle, n) for n in names))
        .where(Vehicle.vehicle_id.in_([row.vehicle_id for row in rows]))
        .with_for_update()
    ).all()
    versions_before = {vehicle.vehicle_id: vehicle.config_version for vehicle in stored}
    fields_before = {vehicle.vehicle_id: vehicle._mapping for vehicle in stored}
    statement = insert(Vehicle).values([row.model_dump() for row in rows])
    if update_existing:
        columns: dict[str, Any] = {name: statement.excluded[name] for name in names}
        # A row that changes what the car is told is a new config, as an assignment through
        # the API is: the version the agent echoes then says whether it has picked it up.
        changed = tuple_(*(getattr(Vehicle, name) for name in names)).is_distinct_from(
            tuple_(*(statement.excluded[name] for name in names))
        )
        columns["config_version"] = case(
            (changed, Vehicle.config_version + 1), else_=Vehicle.config_version
        )
        statement = statement.on_conflict_do_update(index_elements=["vehicle_id"], set_=columns)
    else:
        statement = statement.on_conflict_do_nothing(index_elements=["vehicle_id"])
    written = session.execute(statement.returning(Vehicle.vehicle_id, Vehicle.config_version))
    versions_after = dict(written.all())
    changed_by = "command line: vehicles add" if label is None else f"roster import of {label}"
    for row in rows:
        before = versions_before.get(row.vehicle_id)
        after = versions_after.get(row.vehicle_id)
        if before is not None and after is not None and after != before:
            was = fields_before[row.vehicle_id]
            now = row.model_dump()
            session.add(
                VehicleChange(
                    vehicle_id=row.vehicle_id,
                    config_version=after,
                    changed_by=changed_by,
                    change="roster",
                    lane=row.assigned_lane,
                    route=row.route,
                    controller_name=row.controller_name,
                    controller_params=row.controller_params,
                    roster_changed={
                        name: [was[name], now[name]] for name in names if was[name] != now[name]
                    },
                )
            )
    session.flush()
    return len(versions_after)


def list_vehicles(session: Session) -> Iterable[Vehicle]:
    """The roster in id order."""
    return session.scalars(select(Vehicle).order_by(Vehicle.vehicle_id)).all()
