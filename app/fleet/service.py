"""The fleet's state for operators: every vehicle with its last ping, last status and readiness;
changing a vehicle's assignment or maintenance flag. No HTTP here (API and dashboard share it).
"""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import anyio.to_thread
from sqlalchemy import DateTime, Select, Text, and_, bindparam, func, select, true
from sqlalchemy.dialects.postgresql import ARRAY
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import aliased
from sqlalchemy.sql.selectable import TableValuedAlias

from app.fleet.readiness import (
    CHECK_NAMES,
    CHECKS,
    HOLD_PERIODS_REPLAYED,
    LastPing,
    LastStatus,
    Readiness,
    Thresholds,
    VehicleFacts,
    assess,
    message_age_s,
)
from app.models import (
    Corridor,
    Vehicle,
    VehicleAssignment,
    VehicleChange,
    VehiclePing,
    VehicleStatus,
)
from app.policies.service import policy_controller
from contract.controllers import (
    ControllerConfigError,
    RlParams,
    WrongActuation,
    validate_controller,
)
from contract.units import METRES_PER_MILE
from contract.values import storable_text

log = logging.getLogger(__name__)

# The newest ping is looked for in this window first, so the query touches only the last days'
# ping partitions; vehicles silent for longer are looked up again without the bound.
RECENT_PING_WINDOW = timedelta(days=2)

STATUS_FIELDS = tuple(
    name for name in LastStatus.__dataclass_fields__ if name not in ("ts", "received_at")
)
# fact_vehicle_status's columns in LastStatus's field order (ts and received_at first).
STATUS_COLUMNS = tuple(
    getattr(VehicleStatus, name) for name in ("ts", "received_at", *STATUS_FIELDS)
)


class VehicleNotFound(LookupError):
    """No vehicle with this id in the roster."""


class AssignmentError(ValueError):
    """An assignment the vehicle cannot take: `field` (dotted, e.g. `controller.params.k`) and
    `reason`; the message says both."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class AssignmentConflict(AssignmentError):
    """A well-formed assignment this vehicle cannot take: a lane beyond its corridor's, or a
    controller that cannot drive its actuation (the API's 409; the request itself is valid)."""


@dataclass(frozen=True)
class FleetEntry:
    """One vehicle as operators see it."""

    vehicle: Vehicle
    corridor_lanes: int
    last_ping: LastPing | None
    last_status: LastStatus | None
    readiness: Readiness
    # how far behind the server stored what the fleet sent when this entry was graded
    server_lag_s: float = 0.0
    # The corridor the last ping's x_m lies along: the one the car was assigned at the ping's
    # ts (`dim_vehicle_assignment`, as ingest matched it), and its postmile at x = 0. A car
    # moved to another corridor since is still where its last ping put it, not on its new road.
    ping_corridor_id: str | None = None
    ping_postmile_at_start: float | None = None

    def message_age_s(self, ts: datetime, received_at: datetime, now: datetime) -> float:
        """A message's age as the checks graded it (`readiness.message_age_s`)."""
        clock = now - timedelta(seconds=self.server_lag_s)
        return message_age_s(ts, received_at, clock, self.server_lag_s)

    @property
    def postmile(self) -> float | None:
        """Postmile of the last ping along the corridor it was matched on, if it was on it."""
        ping = self.last_ping
        if ping is None or ping.x_m is None or self.ping_postmile_at_start is None:
            return None
        return self.ping_postmile_at_start + ping.x_m / METRES_PER_MILE

    def has_problem(self, problem: str) -> bool:
        """Whether the vehicle matches a problem filter (see PROBLEM_FILTERS)."""
        # "not cleared" is the verdict the count above the table counts: a car in maintenance
        # or inactive is listed under its own filter, not among the faults
        not_cleared = self.readiness.verdict == "not cleared"
        if problem == "not-cleared":
            return not_cleared
        if problem == "maintenance":
            return self.vehicle.is_in_maintenance
        if problem == "amber":
            return any(check.level == "amber" for check in self.readiness.checks)
        if problem in CHECK_NAMES:
            return self.readiness.level_of(problem) in ("amber", "red")
        if problem.endswith("-red") and problem[:-4] in CHECK_NAMES:
            return not_cleared and self.readiness.level_of(problem[:-4]) == "red"
        raise ValueError(f"unknown problem filter {problem!r}")


PROBLEM_FILTERS: dict[str, str] = {
    "not-cleared": "not cleared",
    "amber": "any amber check",
    "maintenance": "in maintenance",
    **{name: f"{name} amber or red" for name in CHECK_NAMES},
    **{f"{check.name}-red": f"not cleared: {check.label}" for check in CHECKS},
}


@dataclass(frozen=True)
class FleetCounts:
    """The numbers at the top of the fleet page."""

    vehicles: int
    cleared: int
    not_cleared: int
    maintenance: int
    inactive: int
    reporting: int
    engaged: int


def count(entries: Sequence[FleetEntry]) -> FleetCounts:
    """Counts over the given entries (reporting = status check not red)."""
    verdicts = Counter(entry.readiness.verdict for entry in entries)
    return FleetCounts(
        vehicles=len(entries),
        cleared=verdicts["cleared"],
        not_cleared=verdicts["not cleared"],
        maintenance=verdicts["maintenance"],
        inactive=verdicts["inactive"],
        reporting=sum(entry.readiness.level_of("status") != "red" for entry in entries),
        engaged=sum(
            entry.readiness.level_of("ping") != "red"
            and entry.last_ping is not None
            and bool(entry.last_ping.is_controller_engaged)
            for entry in entries
        ),
    )


def select_entries(
    entries: Iterable[FleetEntry],
    *,
    route: str | None = None,
    make: str | None = None,
    problem: str | None = None,
) -> list[FleetEntry]:
    """The entries matching every given filter."""
    if problem is not None and problem not in PROBLEM_FILTERS:
        raise ValueError(f"unknown problem filter {problem!r}")
    return [
        entry
        for entry in entries
        if (route is None or entry.vehicle.route == route)
        and (make is None or entry.vehicle.make == make)
        and (problem is None or entry.has_problem(problem))
    ]


def _to_last_ping(ping: VehiclePing | None) -> LastPing | None:
    if ping is None:
        return None
    return LastPing(
        ts=ping.ts,
        received_at=ping.received_at,
        speed_mps=float(ping.speed_mps),
        x_m=None if ping.x_m is None else float(ping.x_m),
        lane=ping.lane,
        is_acc_engaged=ping.is_acc_engaged,
        is_controller_engaged=ping.is_controller_engaged,
        controller=ping.controller,
        plan_id=ping.plan_id,
        policy_sha256=ping.policy_sha256,
    )


def _to_last_status(status: VehicleStatus | None) -> LastStatus | None:
    if status is None:
        return None
    values: dict[str, Any] = {name: getattr(status, name) for name in STATUS_FIELDS}
    return LastStatus(ts=status.ts, received_at=status.received_at, **values)


def _latest_query(
    recent_since: datetime | None, vehicle_ids: Sequence[str] | None
) -> Select[Vehicle, int, VehiclePing, VehicleStatus]:
    ping_query = select(VehiclePing).where(VehiclePing.vehicle_id == Vehicle.vehicle_id)
    if recent_since is not None:
        ping_query = ping_query.where(VehiclePing.ts >= recent_since)
    last_ping = aliased(
        VehiclePing, ping_query.order_by(VehiclePing.ts.desc()).limit(1).lateral("last_ping")
    )
    last_status = aliased(
        VehicleStatus,
        select(VehicleStatus)
        .where(VehicleStatus.vehicle_id == Vehicle.vehicle_id)
        .order_by(VehicleStatus.ts.desc())
        .limit(1)
        .lateral("last_status"),
    )
    query = (
        select(Vehicle, Corridor.lanes, last_ping, last_status)
        .join(Corridor, Corridor.corridor_id == Vehicle.corridor_id)
        .outerjoin(last_ping, true())
        .outerjoin(last_status, true())
        .order_by(Vehicle.vehicle_id)
    )
    if vehicle_ids is not None:
        query = query.where(Vehicle.vehicle_id.in_(vehicle_ids))
    return query


def _per_vehicle_instants(instants: Mapping[str, datetime], name: str) -> TableValuedAlias:
    """`instants` as a derived table `name` of (vehicle_id, ts) rows, bound as two arrays: one
    join for the whole fleet, where a branch a car made a hundred to build and compile."""
    return (
        func.unnest(
            bindparam("vehicle_ids", list(instants), type_=ARRAY(Text)),
            bindparam("ts", list(instants.values()), type_=ARRAY(DateTime(timezone=True))),
        )
        .table_valued("vehicle_id", "ts")
        .render_derived(name=name)
    )


async def _corridors_at(
    session: AsyncSession, pinged_at: Mapping[str, datetime]
) -> dict[str, tuple[str, float]]:
    """Each vehicle's corridor (id, postmile at x = 0) in force at `pinged_at[vehicle_id]`,
    from the assignment history, as ingest matched the ping to it."""
    if not pinged_at:
        return {}
    pings = _per_vehicle_instants(pinged_at, "last_ping")
    rows = await session.execute(
        select(pings.c.vehicle_id, Corridor.corridor_id, Corridor.postmile_at_start)
        .join(
            VehicleAssignment,
            and_(
                VehicleAssignment.vehicle_id == pings.c.vehicle_id,
                VehicleAssignment.valid_from <= pings.c.ts,
                pings.c.ts < VehicleAssignment.valid_to,
            ),
        )
        .join(Corridor, Corridor.corridor_id == VehicleAssignment.corridor_id)
    )
    return {vehicle_id: (corridor, float(start)) for vehicle_id, corridor, start in rows}


async def _earlier_statuses(
    session: AsyncSession, since: Mapping[str, datetime]
) -> dict[str, list[LastStatus]]:
    """Each vehicle's status reports since its own `since[vehicle_id]`, oldest first (the
    primary key's order)."""
    if not since:
        return {}
    # Columns, not ORM objects: a fleet view reads every car's recent reports, and each is
    # needed only as a LastStatus (an ORM object per report, then copied, cost the view time).
    # Each car's window comes as two arrays joined against the reports, not as one OR branch a
    # car: building and compiling a hundred branches held the event loop for milliseconds a
    # view (`python -m bench.dashboard --profile-fleet 20`).
    windows = _per_vehicle_instants(since, "report_window")
    rows = await session.execute(
        select(VehicleStatus.vehicle_id, *STATUS_COLUMNS)
        .join(
            windows,
            and_(
                VehicleStatus.vehicle_id == windows.c.vehicle_id,
                VehicleStatus.ts >= windows.c.ts,
            ),
        )
        .order_by(VehicleStatus.vehicle_id, VehicleStatus.ts)
    )
    history: dict[str, list[LastStatus]] = {}
    for vehicle_id, *values in rows:
        history.setdefault(vehicle_id, []).append(LastStatus(*values))
    return history


async def _server_lag_s(
    session: AsyncSession,
    now: datetime,
    limits: Thresholds,
    rows: Sequence[Any] | None,
) -> float:
    """How far behind the server stores what the cars send, never more than
    `limits.server_lag_s`: the age checks measure against now less this, but no message is
    younger than the time since the server stored it (`message_age_s`).

    A server that falls behind (a loaded machine, a database wait) stores every car's pings
    late alike; measured against the wall clock, every car would age. How far behind it is, is
    what its freshest path shows: the least, over the cars' newest pings, of the time from a
    ping's measurement to its storing (`received_at - ts`). A car gone silent does not change
    that (its last ping was stored as promptly as ever), so it ages, alone or with the whole
    fleet; measured against the newest ping stored instead, a car reporting alone aged not at
    all until the allowance ran out. A car whose clock runs ahead makes the lag 0, the wall
    clock: the safe side. Only pings received within the allowance count: a car parked since
    last night was stored promptly then, and says nothing of how far behind the server is now
    (counted, it cancelled the allowance for the whole fleet every morning)."""
    if rows is None:
        rows = (await session.execute(_latest_query(now - RECENT_PING_WINDOW, None))).all()
    received_since = now - timedelta(seconds=limits.server_lag_s)
    delays = [
        (row[2].received_at - row[2].ts).total_seconds()
        for row in rows
        if row[2] is not None and row[2].received_at >= received_since
    ]
    return min(max(min(delays, default=0.0), 0.0), limits.server_lag_s)


VERDICT_ORDER = {"not cleared": 0, "maintenance": 1, "inactive": 2, "cleared": 3}


async def fleet(
    session: AsyncSession,
    now: datetime,
    limits: Thresholds,
    *,
    vehicle_id: str | None = None,
) -> list[FleetEntry]:
    """Every vehicle (or one) with its last ping, last status and readiness: the cars that are
    not cleared first (an operator's question at 6 a.m.), then in id order."""
    ids = None if vehicle_id is None else [vehicle_id]
    rows = (await session.execute(_latest_query(now - RECENT_PING_WINDOW, ids))).all()
    silent = [row[0].vehicle_id for row in rows if row[2] is None]
    older: dict[str, VehiclePing | None] = {}
    if silent:
        for row in (await session.execute(_latest_query(None, silent))).all():
            older[row[0].vehicle_id] = row[2]
    # the hold periods replayed run back from each car's newest report, not from now: a server
    # behind its fleet (or a car whose clock is behind) must replay as many as a prompt one
    replayed = timedelta(seconds=HOLD_PERIODS_REPLAYED * limits.hold_s)
    history = await _earlier_statuses(
        session, {row[0].vehicle_id: row[3].ts - replayed for row in rows if row[3] is not None}
    )
    lag_s = await _server_lag_s(session, now, limits, rows if vehicle_id is None else None)
    last_pings = {
        row[0].vehicle_id: ping.ts
        for row in rows
        if (ping := row[2] if row[2] is not None else older.get(row[0].vehicle_id)) is not None
    }
    corridors = await _corridors_at(session, last_pings)
    # Grading is CPU alone, on a worker thread: on the event loop every ping arriving meanwhile
    # waited for it (a batch of 100 pings 73 ms at the median while the fleet page refreshed
    # in a loop, against 7 ms with no page viewed: `python -m bench.dashboard`).
    return await anyio.to_thread.run_sync(
        _graded, rows, older, history, corridors, now, lag_s, limits
    )


def _graded(
    rows: Sequence[Any],
    older: Mapping[str, VehiclePing | None],
    history: Mapping[str, Sequence[LastStatus]],
    corridors: Mapping[str, tuple[str, float]],
    now: datetime,
    lag_s: float,
    limits: Thresholds,
) -> list[FleetEntry]:
    """Each car's entry with its readiness, not cleared first, then in id order."""
    clock = now - timedelta(seconds=lag_s)
    entries = []
    for vehicle, lanes, ping_row, status_row in rows:
        ping_corridor = corridors.get(vehicle.vehicle_id)
        last_ping = _to_last_ping(
            ping_row if ping_row is not None else older.get(vehicle.vehicle_id)
        )
        last_status = _to_last_status(status_row)
        facts = VehicleFacts(
            vehicle_id=vehicle.vehicle_id,
            assigned_controller=vehicle.controller_name,
            is_active=vehicle.is_active,
            is_in_maintenance=vehicle.is_in_maintenance,
            last_ping=last_ping,
            last_status=last_status,
            make=vehicle.make,
            model=vehicle.model,
            year=vehicle.year,
            config_version=vehicle.config_version,
            server_lag_s=lag_s,
            earlier_statuses=tuple(
                status
                for status in history.get(vehicle.vehicle_id, ())
                if last_status is not None and status.ts < last_status.ts
            ),
        )
        entries.append(
            FleetEntry(
                vehicle=vehicle,
                corridor_lanes=int(lanes),
                last_ping=last_ping,
                last_status=last_status,
                readiness=assess(facts, clock, limits),
                server_lag_s=lag_s,
                ping_corridor_id=ping_corridor[0] if ping_corridor else None,
                ping_postmile_at_start=ping_corridor[1] if ping_corridor else None,
            )
        )
    entries.sort(key=lambda entry: VERDICT_ORDER[entry.readiness.verdict])
    return entries


async def vehicle_entry(
    session: AsyncSession, vehicle_id: str, now: datetime, limits: Thresholds
) -> FleetEntry:
    """One vehicle's entry, or VehicleNotFound."""
    entries = await fleet(session, now, limits, vehicle_id=vehicle_id)
    if not entries:
        raise VehicleNotFound(vehicle_id)
    return entries[0]


async def _vehicle_for_update(session: AsyncSession, vehicle_id: str) -> Vehicle:
    vehicle = await session.scalar(
        select(Vehicle).where(Vehicle.vehicle_id == vehicle_id).with_for_update()
    )
    if vehicle is None:
        raise VehicleNotFound(vehicle_id)
    return vehicle


async def _check_policy_held(session: AsyncSession, controller_name: str, sha256: str) -> None:
    """A policy an assignment names must be on the server, for that controller: the car
    downloads it from here, and could run nothing else. A well-formed hash the server does not
    hold is a conflict with the server's state (409), like a lane beyond the corridor."""
    held = await policy_controller(session, sha256)
    field = "controller.params.policy_sha256"
    if held is None:
        raise AssignmentConflict(
            field, f"no policy {sha256} on the server (upload it first: smoothfleet policy upload)"
        )
    if held != controller_name:
        raise AssignmentConflict(
            field, f"policy {sha256[:12]} is a {held} policy, not {controller_name}"
        )


# A route's and a maintenance note's bounds: the API's schema (app.fleet.schemas) states them,
# and the service keeps them for every caller (the dashboard's forms reach only the service).
MAX_ROUTE_LENGTH = 64
MAX_NOTE_LENGTH = 500


def _storable(field: str, text: str) -> None:
    try:
        storable_text(text)
    except ValueError as error:
        raise AssignmentError(field, str(error)) from None


async def change_assignment(
    session: AsyncSession,
    vehicle_id: str,
    *,
    lane: int,
    route: str,
    controller_name: str,
    controller_params: dict[str, Any],
    changed_by: str,
    expected_config_version: int | None = None,
) -> Vehicle:
    """Give a vehicle a new lane, route and controller (the car picks it up with its config).

    With `expected_config_version` (the version the operator's form was filled in against),
    a vehicle changed since by someone else is a conflict: two operators on one car's page
    must not silently overwrite each other."""
    vehicle = await _vehicle_for_update(session, vehicle_id)
    # What is wrong with the assignment itself first (AssignmentError), then what does not fit
    # this vehicle (AssignmentConflict), so a bad request is never answered as a conflict.
    route = route.strip()
    if not route:
        raise AssignmentError("route", "must not be empty")
    # what the API's schema refuses, refused here for every caller (the dashboard's form too)
    if len(route) > MAX_ROUTE_LENGTH:
        raise AssignmentError("route", f"at most {MAX_ROUTE_LENGTH} characters, not {len(route)}")
    _storable("route", route)
    if lane < 1:
        raise AssignmentError("lane", f"lanes are numbered from 1, not {lane}")
    try:
        # the schema the car builds its controller from: a config it cannot run is never saved
        params = validate_controller(controller_name, vehicle.actuation, controller_params)
    except WrongActuation as error:
        raise AssignmentConflict(error.field, error.reason) from None
    except ControllerConfigError as error:
        raise AssignmentError(error.field, error.reason) from None
    _check_unchanged_since(vehicle, expected_config_version, "assignment")
    lanes = await session.scalar(
        select(Corridor.lanes).where(Corridor.corridor_id == vehicle.corridor_id)
    )
    if lanes is None or lane > lanes:
        reason = f"{vehicle.corridor_id} has lanes 1 to {lanes}, not {lane}"
        raise AssignmentConflict("lane", reason)
    if isinstance(params, RlParams) and params.policy_sha256 is not None:
        await _check_policy_held(session, controller_name, params.policy_sha256)
    vehicle.assigned_lane = lane
    vehicle.route = route
    vehicle.controller_name = controller_name
    vehicle.controller_params = controller_params
    _record_change(
        session,
        vehicle,
        changed_by,
        change="assignment",
        lane=lane,
        route=route,
        controller_name=controller_name,
        controller_params=controller_params,
    )
    await session.flush()
    log.info(
        "assignment of %s changed by %s: lane %s, route %s, controller %s",
        vehicle_id,
        changed_by,
        lane,
        route,
        controller_name,
    )
    return vehicle


def _record_change(session: AsyncSession, vehicle: Vehicle, changed_by: str, **what: Any) -> None:
    """A new config version of `vehicle`, and the row of fact_vehicle_change that says who
    made it and what it set, in the change's own transaction."""
    vehicle.config_version += 1
    session.add(
        VehicleChange(
            vehicle_id=vehicle.vehicle_id,
            config_version=vehicle.config_version,
            changed_by=changed_by,
            **what,
        )
    )


def _check_unchanged_since(
    vehicle: Vehicle, expected_config_version: int | None, what: str
) -> None:
    """AssignmentConflict when the operator's form was filled in against an older config: two
    operators on one car's page must not silently overwrite each other."""
    if expected_config_version is not None and expected_config_version != vehicle.config_version:
        raise AssignmentConflict(
            "config_version",
            f"the vehicle was changed since its config v{expected_config_version} was read "
            f"(now v{vehicle.config_version}): check its {what} and save again",
        )


async def set_maintenance(
    session: AsyncSession,
    vehicle_id: str,
    *,
    in_maintenance: bool,
    note: str | None,
    changed_by: str,
    expected_config_version: int | None = None,
) -> Vehicle:
    """Take a vehicle out of (or back into) service; a note says why.

    With `expected_config_version`, as for an assignment: a stale page that shows the car in
    service must not put back in service a car someone has since taken out, nor erase their
    note."""
    if note is not None:
        _storable("note", note)
        if len(note) > MAX_NOTE_LENGTH:
            raise AssignmentError("note", f"at most {MAX_NOTE_LENGTH} characters, not {len(note)}")
    vehicle = await _vehicle_for_update(session, vehicle_id)
    _check_unchanged_since(vehicle, expected_config_version, "maintenance")
    vehicle.is_in_maintenance = in_maintenance
    vehicle.maintenance_note = (note or "").strip() or None
    _record_change(
        session,
        vehicle,
        changed_by,
        change="maintenance",
        in_maintenance=in_maintenance,
        note=vehicle.maintenance_note,
    )
    await session.flush()
    log.info("maintenance of %s set to %s by %s", vehicle_id, in_maintenance, changed_by)
    return vehicle
