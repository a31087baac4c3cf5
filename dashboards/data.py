"""What the pages show, read from the warehouse and the analytics views (async, read-only)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from datetime import datetime, timedelta
from typing import Any
from zoneinfo import ZoneInfo

import numpy as np
from numpy.typing import NDArray
from sqlalchemy import RowMapping, select, text
from sqlalchemy.ext.asyncio import AsyncSession

from app.analytics import view_query
from app.core.metrics import server_registry
from app.models import Corridor, PlanRun
from contract.units import METRES_PER_MILE
from dashboards.corridor_map import MapSegment
from dashboards.figures import Trajectory


async def _rows(session: AsyncSession, sql: str, **params: Any) -> Sequence[RowMapping]:
    return (await session.execute(text(sql), params)).mappings().all()


# --- vehicle ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Trace:
    """A vehicle's pings over a window, and the target of the plan it followed where it was."""

    ts: list[datetime]
    speed_mps: list[float]
    target_mps: list[float | None]
    engaged: list[bool]


async def vehicle_trace(
    session: AsyncSession, vehicle_id: str, last_ts: datetime, window: timedelta
) -> Trace:
    """Pings in (last_ts - window, last_ts] with their plan target (None when no plan)."""
    since = last_ts - window
    pings = await _rows(
        session,
        "SELECT ts, speed_mps, coalesce(is_controller_engaged, false) AS engaged "
        "FROM fact_vehicle_ping WHERE vehicle_id = :vehicle AND ts > :since AND ts <= :until "
        "ORDER BY ts",
        vehicle=vehicle_id,
        since=since,
        until=last_ts,
    )
    targets = await _rows(
        session,
        "SELECT ts, target_speed_mps FROM analytics.plan_adherence "
        "WHERE vehicle_id = :vehicle AND ts > :since AND ts <= :until",
        vehicle=vehicle_id,
        since=since,
        until=last_ts,
    )
    target_at = {row["ts"]: float(row["target_speed_mps"]) for row in targets}
    return Trace(
        ts=[row["ts"] for row in pings],
        speed_mps=[float(row["speed_mps"]) for row in pings],
        target_mps=[target_at.get(row["ts"]) for row in pings],
        engaged=[bool(row["engaged"]) for row in pings],
    )


async def status_history(
    session: AsyncSession, vehicle_id: str, limit: int = 20
) -> Sequence[RowMapping]:
    """The vehicle's newest status reports, newest first."""
    return await _rows(
        session,
        "SELECT * FROM fact_vehicle_status WHERE vehicle_id = :vehicle ORDER BY ts DESC "
        "LIMIT :limit",
        vehicle=vehicle_id,
        limit=limit,
    )


async def vehicle_changes(
    session: AsyncSession, vehicle_id: str, limit: int = 10
) -> Sequence[RowMapping]:
    """The newest changes to the vehicle's assignment, maintenance and roster row, newest first
    (fact_vehicle_change: who, when, what), each maintenance change with `switched`: whether it
    took the car out or put it back, or only changed the note of a car already so (every save
    is a change: read as a fresh "taken out", a note edited named its editor as the one who
    took the car out, and when)."""
    return await _rows(
        session,
        "SELECT * FROM ("
        " SELECT *, in_maintenance IS DISTINCT FROM lag(in_maintenance)"
        "  OVER (PARTITION BY change ORDER BY config_version) AS switched"
        " FROM fact_vehicle_change WHERE vehicle_id = :vehicle"
        ") AS history ORDER BY config_version DESC LIMIT :limit",
        vehicle=vehicle_id,
        limit=limit,
    )


async def out_of_service_since(session: AsyncSession, vehicle_id: str) -> RowMapping | None:
    """The change that took the vehicle out of service this time (`changed_at`, `changed_by`):
    the first marking it out after the last putting it back, however many changes came since
    (read from the ten newest, "since ... by" named a note's editor, or vanished)."""
    rows = await _rows(
        session,
        "SELECT changed_at, changed_by FROM fact_vehicle_change"
        " WHERE vehicle_id = :vehicle AND change = 'maintenance' AND in_maintenance"
        " AND config_version > COALESCE((SELECT max(config_version) FROM fact_vehicle_change"
        "  WHERE vehicle_id = :vehicle AND change = 'maintenance' AND NOT in_maintenance), 0)"
        " ORDER BY config_version LIMIT 1",
        vehicle=vehicle_id,
    )
    return rows[0] if rows else None


async def engagement_per_day(
    session: AsyncSession, since: datetime, zone: ZoneInfo, *, vehicle_id: str | None = None
) -> Sequence[RowMapping]:
    """Share of pings on the corridor with the controller engaged per local day of `zone`, from
    `since` (oldest first; one vehicle's or the fleet's, pooled over pings).

    The figure of analytics.engagement_daily / engagement_fleet_daily, grouped by the day
    people there lived (the field team's days were Central time) instead of the UTC day those
    views export: an evening in Nashville is the next UTC day.
    """
    only = " AND vehicle_id = :vehicle_id" if vehicle_id is not None else ""
    return await _rows(
        session,
        "SELECT (ts AT TIME ZONE :zone)::date AS day, count(*) AS pings, "
        "count(DISTINCT vehicle_id) AS vehicles, "
        "count(*) FILTER (WHERE is_controller_engaged) AS engaged_pings, "
        "(count(*) FILTER (WHERE is_controller_engaged))::double precision / count(*) "
        "AS engagement_share "
        f"FROM fact_vehicle_ping WHERE x_m IS NOT NULL AND ts >= :since{only} "
        "GROUP BY 1 ORDER BY 1",
        zone=zone.key,
        since=since,
        **({"vehicle_id": vehicle_id} if vehicle_id is not None else {}),
    )


async def _view(
    session: AsyncSession, name: str, since: datetime, *, vehicle_id: str | None = None
) -> Sequence[RowMapping]:
    """An analytics view from `since`, through its windowed function (see app.analytics)."""
    sql, params = view_query(name, since=since, vehicle_id=vehicle_id)
    return await _rows(session, sql, **params)


# --- plans --------------------------------------------------------------------------------------


async def corridors(session: AsyncSession) -> list[Corridor]:
    """Every corridor, by id."""
    return list(await session.scalars(select(Corridor).order_by(Corridor.corridor_id)))


async def latest_plan(session: AsyncSession, corridor_id: str) -> PlanRun | None:
    """The newest published plan of the corridor."""
    found: PlanRun | None = await session.scalar(
        select(PlanRun)
        .where(PlanRun.corridor_id == corridor_id, PlanRun.status == "published")
        .order_by(PlanRun.published_at.desc())
        .limit(1)
    )
    return found


async def map_segments(
    session: AsyncSession, corridor_id: str, plan: PlanRun | None
) -> list[MapSegment]:
    """The corridor's sub-segments with their coordinates and, per lane, the plan's target."""
    rows = await _rows(
        session,
        "SELECT s.i24_segment_id, s.start_x_m, s.end_x_m, s.start_lat, s.start_lon, s.end_lat, "
        "s.end_lon, sp.lane, sp.target_speed_mps, sp.is_buffer FROM dim_i24_segment s "
        "LEFT JOIN fact_speed_planner sp ON sp.i24_segment_id = s.i24_segment_id "
        "AND sp.corridor_id = s.corridor_id AND sp.plan_id = :plan "
        "WHERE s.corridor_id = :corridor ORDER BY s.seq, sp.lane",
        corridor=corridor_id,
        plan=-1 if plan is None else plan.plan_id,
    )
    segments: dict[int, MapSegment] = {}
    for row in rows:
        segment = segments.get(row["i24_segment_id"])
        if segment is None:
            segment = MapSegment(
                float(row["start_x_m"]),
                float(row["end_x_m"]),
                float(row["start_lat"]),
                float(row["start_lon"]),
                float(row["end_lat"]),
                float(row["end_lon"]),
                {},
                False,
            )
            segments[row["i24_segment_id"]] = segment
        if row["lane"] is not None:
            segment.target_mps[int(row["lane"])] = float(row["target_speed_mps"])
            if row["is_buffer"]:
                segments[row["i24_segment_id"]] = replace(segment, is_buffer=True)
    return list(segments.values())


async def fleet_trajectories(
    session: AsyncSession, corridor: Corridor, since: datetime, until: datetime, bucket_s: float
) -> list[Trajectory]:
    """Every car's path along the corridor between since and until: its last ping in each
    `bucket_s` window, drawn at that ping's own time and place (a car re-entering at the start
    is not averaged across the corridor; at the bucket's start it would be drawn up to a bucket
    ahead of where it was, 3 km at a day's 120 s), and whether its controller was engaged then."""
    rows = await _rows(
        session,
        "SELECT p.vehicle_id, floor(extract(epoch FROM p.ts) / :bucket) AS bucket, "
        "extract(epoch FROM max(p.ts)) AS t, "
        "(array_agg(p.x_m ORDER BY p.ts DESC))[1] AS x_m, "
        "(array_agg(coalesce(p.is_controller_engaged, false) ORDER BY p.ts DESC))[1] AS engaged "
        # the corridor each ping's car was assigned at its ts, not the car's corridor now
        "FROM fact_vehicle_ping p JOIN dim_vehicle_assignment a ON a.vehicle_id = p.vehicle_id "
        "AND p.ts >= a.valid_from AND p.ts < a.valid_to "
        "WHERE a.corridor_id = :corridor AND p.ts >= :since AND p.ts <= :until "
        "AND p.x_m IS NOT NULL GROUP BY p.vehicle_id, bucket ORDER BY p.vehicle_id, bucket",
        corridor=corridor.corridor_id,
        since=since,
        until=until,
        bucket=bucket_s,
    )
    paths: dict[str, list[RowMapping]] = {}
    for row in rows:
        paths.setdefault(row["vehicle_id"], []).append(row)
    return [
        Trajectory(
            vehicle_id,
            np.array([float(r["t"]) for r in path]),
            corridor.postmile_at_start
            + np.array([float(r["x_m"]) for r in path]) / METRES_PER_MILE,
            np.array([bool(r["engaged"]) for r in path]),
        )
        for vehicle_id, path in paths.items()
    ]


async def engagement_share(
    session: AsyncSession, corridor_id: str, since: datetime, until: datetime
) -> tuple[int, float | None]:
    """(pings on the corridor, share of them with the controller engaged) between the times."""
    row = (
        await _rows(
            session,
            "SELECT count(*) AS pings, avg(coalesce(p.is_controller_engaged, false)::int) "
            "AS share FROM fact_vehicle_ping p "
            "JOIN dim_vehicle_assignment a ON a.vehicle_id = p.vehicle_id "
            "AND p.ts >= a.valid_from AND p.ts < a.valid_to "
            "WHERE a.corridor_id = :corridor AND p.ts >= :since AND p.ts <= :until "
            "AND p.x_m IS NOT NULL",
            corridor=corridor_id,
            since=since,
            until=until,
        )
    )[0]
    return int(row["pings"]), None if row["share"] is None else float(row["share"])


async def plan_by_id(session: AsyncSession, plan_id: int) -> PlanRun | None:
    """A plan run by id (any status)."""
    found: PlanRun | None = await session.scalar(
        select(PlanRun).where(PlanRun.plan_id == plan_id).limit(1)
    )
    return found


async def plan_runs(session: AsyncSession, corridor_id: str, limit: int = 15) -> list[PlanRun]:
    """The corridor's newest planner runs (published, skipped or failed)."""
    return list(
        await session.scalars(
            select(PlanRun)
            .where(PlanRun.corridor_id == corridor_id)
            .order_by(PlanRun.started_at.desc())
            .limit(limit)
        )
    )


@dataclass(frozen=True)
class LaneProfile:
    """A lane of one plan along the corridor (segment edges in postmile, speeds in m/s)."""

    lane: int
    start_postmile: list[float]
    end_postmile: list[float]
    target_mps: list[float]
    tse_mps: list[float | None]
    is_buffer: list[bool]

    def buffers(self) -> list[tuple[float, float]]:
        """Buffer regions as merged (start, end) postmile ranges."""
        regions: list[tuple[float, float]] = []
        for start, end, flag in zip(
            self.start_postmile, self.end_postmile, self.is_buffer, strict=True
        ):
            if not flag:
                continue
            if regions and abs(regions[-1][1] - start) < 1e-6:
                regions[-1] = (regions[-1][0], end)
            else:
                regions.append((start, end))
        return regions


async def plan_profiles(session: AsyncSession, plan: PlanRun) -> list[LaneProfile]:
    """Each lane of the plan along the corridor."""
    rows = await _rows(
        session,
        "SELECT sp.lane, s.start_postmile, s.end_postmile, sp.target_speed_mps, "
        "sp.tse_speed_mps, sp.is_buffer FROM fact_speed_planner sp "
        "JOIN dim_i24_segment s ON s.i24_segment_id = sp.i24_segment_id "
        "WHERE sp.corridor_id = :corridor AND sp.plan_id = :plan ORDER BY sp.lane, s.seq",
        corridor=plan.corridor_id,
        plan=plan.plan_id,
    )
    lanes: dict[int, list[RowMapping]] = {}
    for row in rows:
        lanes.setdefault(int(row["lane"]), []).append(row)
    return [
        LaneProfile(
            lane=lane,
            start_postmile=[float(r["start_postmile"]) for r in lane_rows],
            end_postmile=[float(r["end_postmile"]) for r in lane_rows],
            target_mps=[float(r["target_speed_mps"]) for r in lane_rows],
            tse_mps=[
                None if r["tse_speed_mps"] is None else float(r["tse_speed_mps"]) for r in lane_rows
            ],
            is_buffer=[bool(r["is_buffer"]) for r in lane_rows],
        )
        for lane, lane_rows in sorted(lanes.items())
    ]


@dataclass(frozen=True)
class TimeSpace:
    """Plans of one lane over time: values[plan, segment] (m/s) and where/when they hold."""

    published_at: NDArray[np.float64]  # epoch s, ascending
    valid_until: NDArray[np.float64]
    segment_edges_postmile: NDArray[np.float64]  # segments + 1 edges, ascending
    target_mps: NDArray[np.float64]
    tse_mps: NDArray[np.float64]


async def recent_plans(
    session: AsyncSession, corridor_id: str, lane: int, since: datetime, until: datetime
) -> TimeSpace | None:
    """Published plans of the lane between since and until; None when there are none."""
    segments = await _rows(
        session,
        "SELECT i24_segment_id, start_postmile, end_postmile FROM dim_i24_segment "
        "WHERE corridor_id = :corridor ORDER BY seq",
        corridor=corridor_id,
    )
    rows = await _rows(
        session,
        "SELECT r.plan_id, r.published_at, r.valid_until, sp.i24_segment_id, "
        "sp.target_speed_mps, sp.tse_speed_mps FROM plan_run r "
        "JOIN fact_speed_planner sp ON sp.corridor_id = r.corridor_id AND sp.plan_id = r.plan_id "
        "WHERE r.corridor_id = :corridor AND r.status = 'published' AND sp.lane = :lane "
        "AND r.published_at > :since AND r.published_at <= :until ORDER BY r.published_at",
        corridor=corridor_id,
        lane=lane,
        since=since,
        until=until,
    )
    if not rows or not segments:
        return None
    column = {row["i24_segment_id"]: index for index, row in enumerate(segments)}
    plans: dict[int, int] = {}
    published: list[float] = []
    valid: list[float] = []
    for row in rows:
        if row["plan_id"] not in plans:
            plans[row["plan_id"]] = len(plans)
            published.append(row["published_at"].timestamp())
            valid.append(row["valid_until"].timestamp())
    target = np.full((len(plans), len(segments)), np.nan)
    tse = np.full((len(plans), len(segments)), np.nan)
    for row in rows:
        index = plans[row["plan_id"]], column[row["i24_segment_id"]]
        target[index] = row["target_speed_mps"]
        if row["tse_speed_mps"] is not None:
            tse[index] = row["tse_speed_mps"]
    edges = [float(segments[0]["start_postmile"])] + [float(s["end_postmile"]) for s in segments]
    return TimeSpace(np.array(published), np.array(valid), np.array(edges), target, tse)


def sample_plans(
    field: TimeSpace,
    values: NDArray[np.float64],
    times: NDArray[np.float64],
    postmiles: NDArray[np.float64],
) -> NDArray[np.float64]:
    """values[row = postmile, column = time] of the plan in force at each time (NaN if none)."""
    plan = np.searchsorted(field.published_at, times, side="right") - 1
    in_force = (plan >= 0) & (times < field.valid_until[np.clip(plan, 0, None)])
    segment = np.searchsorted(field.segment_edges_postmile, postmiles, side="right") - 1
    on_road = (segment >= 0) & (segment < values.shape[1])
    grid = values[np.clip(plan, 0, None)][:, np.clip(segment, 0, values.shape[1] - 1)].T
    grid = np.where(in_force[None, :] & on_road[:, None], grid, np.nan)
    result: NDArray[np.float64] = grid.astype(np.float64)
    return result


# --- feeds --------------------------------------------------------------------------------------


async def inrix_snapshots(session: AsyncSession, since: datetime) -> Sequence[RowMapping]:
    """analytics.inrix_latency since `since`, oldest first."""
    return await _rows(
        session,
        "SELECT * FROM analytics.inrix_latency WHERE measured_at >= :since ORDER BY measured_at",
        since=since,
    )


async def latest_inrix(session: AsyncSession) -> RowMapping | None:
    """The newest INRIX snapshot (any corridor)."""
    rows = await _rows(
        session, "SELECT * FROM analytics.inrix_latency ORDER BY measured_at DESC LIMIT 1"
    )
    return rows[0] if rows else None


async def pings_per_minute(session: AsyncSession, since: datetime) -> Sequence[RowMapping]:
    """Pings and vehicles per minute of GPS time from the minute holding `since`, with latency
    percentiles.

    That first minute is counted whole: cut at `since` (the page asks from the second it is
    loaded) it held only the pings after that second and read as a drop in the ping rate.
    """
    return await _rows(
        session,
        "SELECT date_trunc('minute', ts, 'UTC') AS minute, count(*) AS pings, "
        "count(DISTINCT vehicle_id) AS vehicles, "
        "percentile_cont(0.5) WITHIN GROUP (ORDER BY extract(epoch FROM received_at - ts)) "
        "AS latency_p50_s, "
        "percentile_cont(0.95) WITHIN GROUP (ORDER BY extract(epoch FROM received_at - ts)) "
        "AS latency_p95_s "
        "FROM fact_vehicle_ping "
        "WHERE ts >= date_trunc('minute', CAST(:since AS timestamptz), 'UTC') "
        "GROUP BY minute ORDER BY minute",
        since=since,
    )


@dataclass(frozen=True)
class RejectedInputs:
    """Inputs refused by this server since it started, all its workers (Prometheus counters)."""

    pings_accepted: float
    pings_duplicate: float
    pings_rejected: float
    pings_refused: float
    status_rejected: float
    inrix_unknown: float


def rejected_inputs() -> RejectedInputs:
    """Read the ingest counters of this server (all its workers, as /metrics does)."""
    registry = server_registry()

    def sample(name: str, outcome: str) -> float:
        return registry.get_sample_value(name, {"outcome": outcome}) or 0.0

    return RejectedInputs(
        pings_accepted=sample("smoothfleet_pings_total", "accepted"),
        pings_duplicate=sample("smoothfleet_pings_total", "duplicate"),
        pings_rejected=sample("smoothfleet_pings_total", "rejected"),
        pings_refused=sample("smoothfleet_pings_total", "refused"),
        status_rejected=sample("smoothfleet_status_reports_total", "rejected"),
        inrix_unknown=sample("smoothfleet_inrix_segments_total", "unknown"),
    )


# --- analytics ----------------------------------------------------------------------------------


async def fleet_pings_hourly(session: AsyncSession, since: datetime) -> Sequence[RowMapping]:
    """analytics.fleet_ping_hourly from `since`'s hour."""
    return await _view(session, "fleet_ping_hourly", since)


async def adherence_per_day(
    session: AsyncSession, since: datetime, zone: ZoneInfo
) -> Sequence[RowMapping]:
    """Plan adherence over the fleet (pooled over pings) per local day of `zone`, from `since`:
    analytics.plan_adherence_daily's figures by the local day (see `engagement_per_day`)."""
    return await _rows(
        session,
        "SELECT (ts AT TIME ZONE :zone)::date AS day, count(*) AS pings, "
        "avg(abs(speed_error_mps)) AS mean_abs_speed_error_mps, "
        "avg(speed_error_mps) AS mean_speed_error_mps "
        "FROM analytics.plan_adherence WHERE ts >= :since GROUP BY 1 ORDER BY 1",
        zone=zone.key,
        since=since,
    )


async def newest_ping_ts(session: AsyncSession) -> datetime | None:
    """GPS time of the newest ping of the fleet."""
    found: datetime | None = (
        await session.execute(text("SELECT max(ts) FROM fact_vehicle_ping"))
    ).scalar_one()
    return found


async def edie_field(
    session: AsyncSession, since: datetime, until: datetime, corridor_id: str
) -> Sequence[RowMapping]:
    """analytics.edie_field (paper's 10 s x 200 m boxes) of one corridor over a window."""
    return await _rows(
        session,
        "SELECT * FROM analytics.edie_field(:since, :until) WHERE corridor_id = :corridor",
        since=since,
        until=until,
        corridor=corridor_id,
    )
