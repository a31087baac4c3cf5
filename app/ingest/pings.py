"""From a request body to rows: parse, check the token's authority, validate item by item.

Pure functions over the parsed body and a fleet directory snapshot (no I/O), so every rule of
ingest is testable on its own and the hot path allocates no ORM objects.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import NamedTuple

import orjson
from pydantic import ConfigDict, ValidationError

from app.auth import Principal
from app.core.json_keys import RepeatedKey, refuse_repeated_keys
from app.ingest.directory import CorridorInfo, FleetDirectory
from contract.values import first_problem
from contract.vehicles import MAX_PINGS_PER_BATCH, VEHICLE_ID_PATTERN, Ping, PingBatch

REQUIRED_FIELDS = ("vehicle_id", "ts", "lat", "lon", "speed_mps")


class BodyError(ValueError):
    """The body is not a ping or a batch at all (answered 422)."""


class ForeignVehicle(PermissionError):
    """A vehicle token posted a ping of another vehicle (answered 403, nothing stored)."""

    def __init__(self, message: str, pings: int) -> None:
        super().__init__(message)
        self.pings = pings


class PingRow(NamedTuple):
    """A validated ping in fact_vehicle_ping's column order, with its corridor for map-matching."""

    vehicle_id: str
    ts: datetime
    received_at: datetime
    lat: float
    lon: float
    speed_mps: float
    accel_mps2: float | None
    heading_deg: float | None
    lane: int | None
    is_acc_engaged: bool | None
    is_controller_engaged: bool | None
    controller: str | None
    acc_speed_setting_mph: float | None
    acc_gap_setting: int | None
    is_lead_present: bool | None
    lead_distance_m: float | None
    lead_rel_speed_mps: float | None
    plan_id: int | None
    policy_sha256: str | None
    corridor: CorridorInfo


@dataclass(frozen=True)
class Rejected:
    """A ping refused on its own: its index in the request and why."""

    index: int
    error: str
    # the same ping may pass later: the clock or the roster it was judged against may change
    retryable: bool = False


@dataclass(frozen=True)
class TimeWindow:
    """The accepted range of `ts`: not older than retention, not too far in the future."""

    earliest: datetime
    latest: datetime
    retention_days: int
    max_future_s: float

    @classmethod
    def around(cls, now: datetime, *, retention_days: int, max_future_s: float) -> TimeWindow:
        """The window for a request received at `now`."""
        return cls(
            earliest=now - timedelta(days=retention_days),
            latest=now + timedelta(seconds=max_future_s),
            retention_days=retention_days,
            max_future_s=max_future_s,
        )


def parse_body(body: bytes) -> tuple[list[object], bool]:
    """The items of a body holding one ping or `{"pings": [...]}` and whether it was the
    batch; BodyError otherwise."""
    try:
        document = orjson.loads(body)
    except orjson.JSONDecodeError as error:
        document = _lenient_json(body, error)
    if not isinstance(document, dict):
        raise BodyError('body must be a ping object or {"pings": [...]}')
    # a lone ping may carry fields it does not know, "pings" among them (Ping ignores them)
    lone_ping = any(name in document for name in REQUIRED_FIELDS)
    if lone_ping and isinstance(document.get("pings"), list):
        # read as the batch, the ping's own fields were dropped with a 200 that stored nothing
        present = ", ".join(name for name in REQUIRED_FIELDS if name in document)
        raise BodyError(
            f'body is both a ping (it has {present}) and a batch ("pings": [...]): send the '
            "ping alone or inside the batch"
        )
    if "pings" in document and (isinstance(document["pings"], list) or not lone_ping):
        items = document["pings"]
        if not isinstance(items, list):
            raise BodyError('"pings" must be a list of ping objects')
        if len(items) > MAX_PINGS_PER_BATCH:
            raise BodyError(
                f"a batch holds at most {MAX_PINGS_PER_BATCH} pings, this one has {len(items)}"
            )
        return items, True
    if not lone_ping:
        raise BodyError(
            'body is neither a ping (vehicle_id, ts, lat, lon, speed_mps) nor {"pings": [...]}'
        )
    return [document], False


def _lenient_json(body: bytes, strict_error: orjson.JSONDecodeError) -> object:
    """The body as Python's json module reads it, for what orjson refuses but is not garbage.

    `json.dumps` writes NaN, Infinity and -Infinity by default, and a number like 1e999, an
    integer of 5,000 digits or an escaped lone surrogate is valid JSON syntax; read this way,
    such a value is refused by validation with its item's index, and the other pings of the
    batch are kept.
    """
    try:
        return json.loads(body, parse_int=_integer_or_overflow)
    except (ValueError, RecursionError):
        raise BodyError(f"body is not JSON: {strict_error}") from None


# Python's int() refuses longer integer text (a ValueError that refused the whole body, every
# good ping of the batch with it); no field holds one anyway.
_INT_MAX_DIGITS = 4300


def _integer_or_overflow(text: str) -> int | float:
    """An integer's value, or an infinity of its sign when it is too long to read: validation
    then refuses its item alone, as it refuses 1e999."""
    if len(text.lstrip("-")) > _INT_MAX_DIGITS:
        return -math.inf if text.startswith("-") else math.inf
    return int(text)


VEHICLE_ID_RE = re.compile(VEHICLE_ID_PATTERN)


def _is_vehicle_id(value: object) -> bool:
    return isinstance(value, str) and VEHICLE_ID_RE.fullmatch(value) is not None


def _refuse_foreign(vehicle_ids: Iterable[object], principal: Principal, count: int) -> None:
    """Refuse the whole request if a vehicle token carries another vehicle's ping."""
    if principal.role != "vehicle":
        return
    for vehicle_id in vehicle_ids:
        if vehicle_id is not None and vehicle_id != principal.vehicle_id:
            raise ForeignVehicle(
                f"this token belongs to vehicle {principal.vehicle_id} and may not post "
                f"pings of {vehicle_id!r}; nothing of this request was stored",
                count,
            )


def _describe(error: ValidationError) -> str:
    return str(first_problem(error))


class _BareBatch(PingBatch):
    """A batch with no other field beside "pings", the shape the agent sends: the one-pass
    path's. Anything else (a ping's own fields beside a list of pings) goes item by item,
    where `parse_body` decides it."""

    model_config = ConfigDict(extra="forbid")


def _all_valid(body: bytes) -> list[Ping] | None:
    """Every ping of a body in which all pings are valid, parsed in one pass; None otherwise.

    The common case (a car's own well-formed upload) is validated straight from the bytes by
    pydantic-core; any doubt (an invalid item, another shape) returns None, and the body then
    takes the item-by-item path, which decides what is accepted and how errors are worded.
    """
    try:
        if b'"pings"' in body:
            return _BareBatch.model_validate_json(body).pings
        return [Ping.model_validate_json(body)]
    except ValidationError:
        return None


def read_pings(body: bytes, principal: Principal) -> tuple[list[tuple[int, Ping]], list[Rejected]]:
    """The body's well-formed pings (with their index) and the rejection of each other item.

    BodyError when the body is not a ping or a batch, or is a lone ping that is not valid (a
    batch keeps its good pings; a lone ping has nothing to keep, and the body violates the
    documented schema); ForeignVehicle when a vehicle token carries another vehicle's ping
    (valid or not).
    """
    try:
        refuse_repeated_keys(body)
    except RepeatedKey as error:
        raise BodyError(str(error)) from None
    quick = _all_valid(body)
    if quick is not None:
        _refuse_foreign((ping.vehicle_id for ping in quick), principal, len(quick))
        return list(enumerate(quick)), []
    items, batch = parse_body(body)
    # Only a vehicle id another car could have is another car's ping: a number or an empty
    # string in the field is a malformed item, refused on its own below like any other, not
    # the whole request refused as if the token had posted for someone else.
    _refuse_foreign(
        (
            item.get("vehicle_id")
            for item in items
            if isinstance(item, dict) and _is_vehicle_id(item.get("vehicle_id"))
        ),
        principal,
        len(items),
    )
    pings: list[tuple[int, Ping]] = []
    rejected: list[Rejected] = []
    for index, item in enumerate(items):
        if not isinstance(item, dict):
            rejected.append(Rejected(index, "a ping must be a JSON object"))
            continue
        try:
            pings.append((index, Ping.model_validate(item)))
        except ValidationError as error:
            rejected.append(Rejected(index, _describe(error)))
    if rejected and not batch:
        raise BodyError(f"not a valid ping: {rejected[0].error}")
    return pings, rejected


def check_in_context(
    pings: Sequence[tuple[int, Ping]],
    directory: FleetDirectory,
    window: TimeWindow,
    received_at: datetime,
) -> tuple[list[PingRow], list[Rejected]]:
    """Rows for the pings that fit the roster, the corridor and the clock; rejections else.

    A ping's lane is checked against, and its row carries, the corridor its vehicle was
    assigned at the ping's `ts`: a late ping from before a move keeps its own corridor.
    """
    rows: list[PingRow] = []
    rejected: list[Rejected] = []
    for index, ping in pings:
        # before the roster: a ping older than retention is refused for good, whoever sent it
        # (an unknown vehicle's is retryable, and the car kept resending it in vain)
        if ping.ts < window.earliest:
            rejected.append(
                Rejected(
                    index, f"ts is older than the {window.retention_days}-day retention window"
                )
            )
            continue
        corridor = directory.corridor_of(ping.vehicle_id, ping.ts)
        if corridor is None:
            rejected.append(Rejected(index, f"unknown vehicle {ping.vehicle_id}", retryable=True))
            continue
        if ping.lane is not None and ping.lane > corridor.lanes:
            rejected.append(
                Rejected(
                    index,
                    f"lane {ping.lane} is outside the {corridor.lanes} lanes of "
                    f"{corridor.corridor_id}",
                )
            )
            continue
        if ping.ts > window.latest:
            rejected.append(
                Rejected(
                    index,
                    f"ts is more than {window.max_future_s:g} s in the future",
                    retryable=True,
                )
            )
            continue
        rows.append(
            PingRow(
                ping.vehicle_id,
                ping.ts,
                received_at,
                ping.lat,
                ping.lon,
                ping.speed_mps,
                ping.accel_mps2,
                ping.heading_deg,
                ping.lane,
                ping.acc_engaged,
                ping.controller_engaged,
                ping.controller,
                ping.acc_speed_setting_mph,
                ping.acc_gap_setting,
                ping.lead_present,
                ping.lead_distance_m,
                ping.lead_rel_speed_mps,
                ping.plan_id,
                ping.policy_sha256,
                corridor,
            )
        )
    return rows, rejected
