"""Read plans for the API: the latest valid plan of a corridor, a lane's targets, the history.

A published plan never changes, so its rendered document is cached per (plan_id, lane) in the
application (one cache per app and database: plan ids are only unique within a database): the
fleet polling every few seconds costs one indexed lookup of the latest plan_id per request.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import orjson
from sqlalchemy import text
from sqlalchemy.ext.asyncio import AsyncSession

from app.plans.schemas import PlanRunOut
from contract.plans import BufferOut, LanePlanOut

# Rendered plan documents kept per process (a few lanes of the last few plans).
CACHED_DOCUMENTS = 64
# Targets and positions are served to the millimetre per second / millimetre.
DECIMALS = 3


class PlanDocuments:
    """The most recently served plan documents of one application, least recent dropped."""

    def __init__(self, size: int = CACHED_DOCUMENTS) -> None:
        self.size = size
        self._bodies: OrderedDict[tuple[int, int | None], bytes] = OrderedDict()

    def get(self, plan_id: int, lane: int | None) -> bytes | None:
        """The cached document, or None."""
        body = self._bodies.get((plan_id, lane))
        if body is not None:
            self._bodies.move_to_end((plan_id, lane))
        return body

    def put(self, plan_id: int, lane: int | None, body: bytes) -> None:
        """Keep a rendered document."""
        self._bodies[(plan_id, lane)] = body
        while len(self._bodies) > self.size:
            self._bodies.popitem(last=False)


@dataclass(frozen=True)
class CurrentAssignment:
    """Where a vehicle drives, and the version of its config that says so."""

    corridor_id: str
    assigned_lane: int
    config_version: int


@dataclass
class HeldPlans:
    """What this process last read for each corridor and vehicle, so it keeps serving plans while
    its database is away: a plan is valid until its own valid_until, whoever can reach what."""

    lanes: dict[str, int] = field(default_factory=dict)
    plans: dict[str, tuple[int, datetime]] = field(default_factory=dict)
    assignments: dict[str, CurrentAssignment] = field(default_factory=dict)

    def valid_plan_id(self, corridor_id: str, now: datetime) -> int | None:
        """The corridor's last served plan if it is still valid at `now`."""
        held = self.plans.get(corridor_id)
        return held[0] if held is not None and held[1] > now else None


async def corridor_lanes(session: AsyncSession, corridor_id: str) -> int | None:
    """How many lanes the corridor has, or None if it is unknown."""
    lanes = await session.scalar(
        text("SELECT lanes FROM dim_corridor WHERE corridor_id = :corridor"),
        {"corridor": corridor_id},
    )
    return None if lanes is None else int(lanes)


async def vehicle_assignment(session: AsyncSession, vehicle_id: str) -> CurrentAssignment | None:
    """The vehicle's corridor, assigned lane and config version, or None if it is unknown."""
    row = (
        await session.execute(
            text(
                "SELECT corridor_id, assigned_lane, config_version FROM dim_vehicle "
                "WHERE vehicle_id = :vehicle"
            ),
            {"vehicle": vehicle_id},
        )
    ).first()
    if row is None:
        return None
    return CurrentAssignment(str(row.corridor_id), int(row.assigned_lane), int(row.config_version))


async def latest_valid_plan(
    session: AsyncSession, corridor_id: str, now: datetime
) -> tuple[int, datetime] | None:
    """The newest published plan of the corridor still valid at `now`: (plan_id, valid_until)."""
    row = (
        await session.execute(
            text(
                "SELECT plan_id, valid_until FROM plan_run WHERE corridor_id = :corridor "
                "AND status = 'published' AND published_at <= :now AND valid_until > :now "
                "ORDER BY published_at DESC LIMIT 1"
            ),
            {"corridor": corridor_id, "now": now},
        )
    ).first()
    return None if row is None else (int(row.plan_id), row.valid_until)


def _buffers(
    starts: list[float], ends: list[float], targets: list[float], flags: list[bool]
) -> list[BufferOut]:
    buffers: list[BufferOut] = []
    run_start: int | None = None
    for index, flag in enumerate([*flags, False]):
        if flag and run_start is None:
            run_start = index
        elif not flag and run_start is not None:
            buffers.append(
                BufferOut(
                    start_x_m=starts[run_start],
                    end_x_m=ends[index - 1],
                    target_speed_mps=min(targets[run_start:index]),
                )
            )
            run_start = None
    return buffers


async def plan_document(
    session: AsyncSession,
    documents: PlanDocuments,
    corridor_id: str,
    plan_id: int,
    lane: int | None,
) -> bytes:
    """The plan as JSON (interfaces.md shape), all lanes or one."""
    cached = documents.get(plan_id, lane)
    if cached is not None:
        return cached
    run = (
        await session.execute(
            text(
                "SELECT plan_id, corridor_id, published_at, valid_until, algorithm, params, inputs "
                "FROM plan_run WHERE corridor_id = :corridor AND plan_id = :plan_id"
            ),
            {"corridor": corridor_id, "plan_id": plan_id},
        )
    ).one()
    rows = (
        await session.execute(
            text(
                "SELECT p.lane, s.start_x_m, s.end_x_m, s.start_postmile, p.target_speed_mps, "
                "p.is_buffer FROM fact_speed_planner p "
                "JOIN dim_i24_segment s ON s.i24_segment_id = p.i24_segment_id "
                "WHERE p.corridor_id = :corridor AND p.plan_id = :plan_id "
                "AND (CAST(:lane AS smallint) IS NULL OR p.lane = :lane) "
                "ORDER BY p.lane, s.start_x_m"
            ),
            {"corridor": corridor_id, "plan_id": plan_id, "lane": lane},
        )
    ).all()
    by_lane: dict[int, list[Any]] = {}
    for row in rows:
        by_lane.setdefault(int(row.lane), []).append(row)
    lanes = []
    for lane_number, lane_rows in by_lane.items():
        starts = [round(float(row.start_x_m), DECIMALS) for row in lane_rows]
        ends = [round(float(row.end_x_m), DECIMALS) for row in lane_rows]
        targets = [round(float(row.target_speed_mps), DECIMALS) for row in lane_rows]
        lanes.append(
            LanePlanOut(
                lane=lane_number,
                x_m=starts,
                end_x_m=ends,
                postmile=[round(float(row.start_postmile), 4) for row in lane_rows],
                target_speed_mps=targets,
                buffers=_buffers(starts, ends, targets, [bool(row.is_buffer) for row in lane_rows]),
            )
        )
    document = {
        "plan_id": int(run.plan_id),
        "corridor": run.corridor_id,
        "published_at": run.published_at,
        "valid_until": run.valid_until,
        "algorithm": run.algorithm,
        "params": run.params,
        "inputs": run.inputs,
        "lanes": [lane_plan.model_dump() for lane_plan in lanes],
    }
    body = orjson.dumps(document)
    documents.put(plan_id, lane, body)
    return body


async def plan_history(
    session: AsyncSession,
    corridor_id: str | None,
    since: datetime | None,
    until: datetime | None,
    status: str | None,
    limit: int,
) -> list[PlanRunOut]:
    """Planner runs started in [since, until), newest first."""
    rows = (
        await session.execute(
            text(
                "SELECT plan_id, corridor_id AS corridor, status, reason, algorithm, params, "
                "inputs, started_at, published_at, valid_until, duration_ms FROM plan_run "
                "WHERE (CAST(:corridor AS text) IS NULL OR corridor_id = :corridor) "
                "AND (CAST(:since AS timestamptz) IS NULL OR started_at >= :since) "
                "AND (CAST(:until AS timestamptz) IS NULL OR started_at < :until) "
                "AND (CAST(:status AS text) IS NULL OR status = :status) "
                "ORDER BY started_at DESC, plan_id DESC LIMIT :limit"
            ),
            {
                "corridor": corridor_id,
                "since": since,
                "until": until,
                "status": status,
                "limit": limit,
            },
        )
    ).mappings()
    return [PlanRunOut.model_validate(dict(row)) for row in rows]
