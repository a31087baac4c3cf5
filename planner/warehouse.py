"""The planner's database edge: read one cycle's inputs, publish its plan, replay a stored one.

One cycle runs in the caller's transaction (`run_cycle(session, ...)`): the plan_run row and all
lanes' fact_speed_planner rows commit together, so a vehicle never sees half a plan. A
PostgreSQL advisory lock per corridor, taken for the transaction, lets only one planner publish
for a corridor even when several replicas run the schedule. The fleet's per-vehicle observations
of the window (fact_vehicle_observation) are written right after, in their own transaction
(`store_window_observations`): at 10,000 vehicles they are ~170,000 rows whose foreign-key
checks alone take seconds, which must not delay the plan (docs/performance.md).

Everything a plan was made from is recorded so `replay_plan` can recompute it from the
warehouse: INRIX rows measured in the history window and received before the run started, the
fleet's observations of the ping window, the earlier plans whose smoothed profiles told
standing bottlenecks from moving waves, the algorithm and parameters.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any, Literal

import numpy as np
from sqlalchemy import Row, text
from sqlalchemy.orm import Session

from planner.algorithms import plan_speeds
from planner.inputs import (
    CorridorGrid,
    EngagedPings,
    FloatArray,
    InrixHistory,
    LaneObservations,
    clean_inrix_speeds,
)
from planner.params import PlannerParams
from planner.pipeline import Plan, PlannerInputs
from planner.predict import NoInrixEstimate

# First key of the planner's advisory locks (the second is the corridor's hash): "SP".
PLANNER_LOCK_SPACE = 0x5350
# A replayed target matches when within this of the stored one (stored as 4-byte REAL).
REPLAY_TOLERANCE_MPS = 1e-3

CycleStatus = Literal["published", "skipped", "failed", "busy"]


class UnknownCorridor(LookupError):
    """The corridor is not in dim_corridor or has no sub-segments."""


class UnknownPlan(LookupError):
    """No plan_run with that plan_id."""


@dataclass(frozen=True)
class CycleOutcome:
    """What one cycle did for one corridor (busy: another planner holds the corridor)."""

    corridor_id: str
    status: CycleStatus
    plan_id: int | None = None
    reason: str | None = None
    duration_ms: float = 0.0
    inputs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ReplayReport:
    """A stored plan against its recomputation from the warehouse."""

    plan_id: int
    corridor_id: str
    algorithm: str
    cells: int
    max_difference_mps: float
    buffer_cells_differing: int

    @property
    def matches(self) -> bool:
        """Same targets (within the REAL column's precision) and the same buffer cells."""
        return self.max_difference_mps <= REPLAY_TOLERANCE_MPS and self.buffer_cells_differing == 0


@dataclass(frozen=True)
class InrixWindow:
    """The INRIX history read for a cycle and what was refused from it."""

    history: InrixHistory
    ignored: dict[str, int]
    measured_at: list[datetime] = field(default_factory=list)  # the snapshots read, in order
    # Per snapshot read, the corridor's segments it held no reading of when read (snapshots
    # read whole are left out): a reading of one stored later must not enter a replay.
    unread: dict[datetime, list[str]] = field(default_factory=dict)


@dataclass(frozen=True)
class PingWindow:
    """The fleet's observations of a cycle's ping window and its counts."""

    observations: LaneObservations
    vehicles: int
    pings: int
    pings_off_corridor: int
    # engaged cars' pings with no leader in radar range, under the "behind_leader" rule
    pings_set_aside: int


def _epoch_s(moment: datetime) -> float:
    return moment.timestamp()


def _iso(moment: datetime) -> str:
    return moment.astimezone(UTC).isoformat()


def corridor_ids(session: Session) -> list[str]:
    """Every corridor in the warehouse."""
    return list(session.scalars(text("SELECT corridor_id FROM dim_corridor ORDER BY corridor_id")))


def load_grid(session: Session, corridor_id: str) -> CorridorGrid:
    """The corridor's fine grid and legal range."""
    corridor = (
        session.execute(
            text(
                "SELECT corridor_id, lanes, speed_limit_mps, min_target_speed_mps "
                "FROM dim_corridor WHERE corridor_id = :corridor"
            ),
            {"corridor": corridor_id},
        )
        .mappings()
        .first()
    )
    if corridor is None:
        raise UnknownCorridor(f"unknown corridor {corridor_id!r}")
    segments = (
        session.execute(
            text(
                "SELECT i24_segment_id, start_x_m, end_x_m FROM dim_i24_segment "
                "WHERE corridor_id = :corridor ORDER BY start_x_m"
            ),
            {"corridor": corridor_id},
        )
        .mappings()
        .all()
    )
    if not segments:
        raise UnknownCorridor(f"corridor {corridor_id!r} has no sub-segments")
    return CorridorGrid.from_rows(dict(corridor), [dict(segment) for segment in segments])


def load_inrix(
    session: Session,
    corridor_id: str,
    now: datetime,
    params: PlannerParams,
    received_by: datetime,
    measured_at: Collection[datetime] | None = None,
    unread: Mapping[datetime, Collection[str]] | None = None,
) -> InrixWindow:
    """INRIX speeds measured in the history window before `now`, received by `received_by`
    (and, for a replay, only of the snapshots `measured_at` the cycle read, without the
    segments each held no reading of then: `unread`).

    `received_at` is when the server stored a reading, so none received after `received_by`
    was there to read; `fetched_at` is not the test: a reading the poller fetched before the
    cycle and stored after it (its backlog while the database was away) was not read either.
    A reading received before the read may still commit after it; `measured_at` and `unread`,
    recorded by the cycle, keep those out of its replay."""
    segments = session.execute(
        text(
            "SELECT xd_code, (start_x_m + end_x_m) / 2 AS center_x_m FROM dim_inrix_segment "
            "WHERE corridor_id = :corridor ORDER BY seq"
        ),
        {"corridor": corridor_id},
    ).all()
    if not segments:
        raise UnknownCorridor(f"corridor {corridor_id!r} has no INRIX segments")
    column = {code: index for index, (code, _) in enumerate(segments)}
    rows = session.execute(
        text(
            "SELECT xd_code, measured_at, speed_mps, is_closed, score FROM fact_inrix_estimate "
            "WHERE corridor_id = :corridor AND measured_at > :since AND measured_at <= :now "
            "AND received_at <= :received_by ORDER BY measured_at"
        ),
        {
            "corridor": corridor_id,
            "since": now - timedelta(seconds=params.inrix_history_s),
            "now": now,
            "received_by": received_by,
        },
    ).all()
    if measured_at is not None:
        rows = [row for row in rows if row.measured_at in measured_at]
    if unread is not None:
        rows = [row for row in rows if row.xd_code not in unread.get(row.measured_at, ())]
    times = sorted({row.measured_at for row in rows})
    read: dict[datetime, set[str]] = {moment: set() for moment in times}
    for row in rows:
        read[row.measured_at].add(row.xd_code)
    segments_unread = {
        moment: codes
        for moment in times
        if (codes := [code for code in column if code not in read[moment]])
    }
    snapshot = {moment: index for index, moment in enumerate(times)}
    speeds = np.full((len(times), len(segments)), np.nan)
    unknown = closed = low_score = not_a_number = 0
    for row in rows:
        if row.xd_code not in column:
            unknown += 1
        elif row.is_closed:
            closed += 1
        elif row.score is not None and row.score < params.min_inrix_score:
            low_score += 1  # a feed that sends no score is taken at its word
        elif row.speed_mps is None or not math.isfinite(row.speed_mps):
            not_a_number += 1
        else:
            speeds[snapshot[row.measured_at], column[row.xd_code]] = row.speed_mps
    # Only the range check is left to do: a cell without a usable row is NaN already.
    cleaned, cleaning = clean_inrix_speeds(speeds)
    history = InrixHistory(
        measured_at_s=np.array([_epoch_s(moment) for moment in times]),
        speed_mps=cleaned.reshape(len(times), len(segments)),
        segment_center_x_m=np.array([center for _, center in segments], dtype=np.float64),
    )
    ignored = {
        "unknown_segment": unknown,
        "closed": closed,
        "below_min_score": low_score,
        "not_a_number": not_a_number,
        "out_of_range": cleaning.out_of_range,
    }
    return InrixWindow(history, ignored, times, segments_unread)


# Per vehicle, lane and sub-segment of the window (cell = -1: off the corridor, x_m NULL or
# beyond its ends); the cycle pools these per lane and cell, the observation table keeps them.
# A ping counts in the corridor and lane its vehicle was assigned at the ping's `ts`
# (`dim_vehicle_assignment`), as ingest map-matched it and the analytics views read it: the
# vehicle's assignment now put the last minute's pings of a car just moved in its new lane, or
# on its new corridor at positions measured along the old one.
# `traffic`: whether the pings tell the traffic's speed under the cycle's `engaged_pings` rule
# (`planner.inputs.traffic_pings`; a flag the car did not send reads as false).
PER_VEHICLE = """
    SELECT p.vehicle_id,
           coalesce(p.lane, a.assigned_lane) AS lane,
           CASE WHEN p.x_m IS NULL OR p.x_m < :first_start OR p.x_m >= :last_end THEN -1
                ELSE width_bucket(p.x_m::float8, CAST(:starts AS float8[])) END AS cell,
           (:engaged_pings = 'all' OR p.is_controller_engaged IS NOT TRUE
            OR p.is_lead_present IS TRUE) AS traffic,
           sum(p.speed_mps::float8) AS speed_sum,
           count(*) AS pings
    FROM fact_vehicle_ping p
    JOIN dim_vehicle_assignment a
      ON a.vehicle_id = p.vehicle_id AND p.ts >= a.valid_from AND p.ts < a.valid_to
    WHERE a.corridor_id = :corridor AND p.ts > :window_start AND p.ts <= :window_end
    GROUP BY 1, 2, 3, 4
"""

# Rows: per (lane, cell) fused; the totals (lane and cell NULL); off the corridor (cell -1);
# set aside by the rule, on the corridor or off (cell -2).
POOL_PINGS = text(
    f"""
    WITH per_vehicle AS ({PER_VEHICLE})
    SELECT lane, cell, sum(speed_sum) / sum(pings) AS mean_speed_mps, sum(pings) AS ping_count,
           count(DISTINCT vehicle_id) AS vehicles
    FROM per_vehicle
    WHERE traffic AND cell >= 1 AND lane BETWEEN 1 AND :lanes
    GROUP BY GROUPING SETS ((lane, cell), ())
    UNION ALL
    SELECT NULL, -1, NULL, sum(pings), NULL FROM per_vehicle WHERE traffic AND cell = -1
    UNION ALL
    SELECT NULL, -2, NULL, sum(pings), NULL FROM per_vehicle WHERE NOT traffic
    """
)

STORE_OBSERVATIONS = text(
    f"""
    WITH per_vehicle AS ({PER_VEHICLE})
    INSERT INTO fact_vehicle_observation
        (vehicle_id, window_end, i24_segment_id, lane, window_start, corridor_id,
         mean_speed_mps, ping_count)
    SELECT vehicle_id, :window_end, (CAST(:segment_ids AS integer[]))[cell], lane,
           :window_start, :corridor, speed_sum / pings, pings
    FROM per_vehicle
    WHERE cell >= 1 AND lane BETWEEN 1 AND :lanes
    ON CONFLICT (vehicle_id, window_end, i24_segment_id, lane) DO UPDATE
        SET window_start = excluded.window_start,
            mean_speed_mps = excluded.mean_speed_mps,
            ping_count = excluded.ping_count
    """
)

POOLED_OBSERVATIONS = text(
    """
    SELECT lane, cell, sum(mean_speed_mps::float8 * ping_count) / sum(ping_count)
               AS mean_speed_mps,
           sum(ping_count) AS ping_count, count(DISTINCT vehicle_id) AS vehicles
    FROM fact_vehicle_observation
    JOIN unnest(CAST(:segment_ids AS integer[])) WITH ORDINALITY AS grid (i24_segment_id, cell)
        USING (i24_segment_id)
    WHERE corridor_id = :corridor AND window_end = :window_end
    GROUP BY GROUPING SETS ((lane, cell), ())
    """
)


def _window_params(
    grid: CorridorGrid, window_start: datetime, window_end: datetime, engaged_pings: EngagedPings
) -> dict[str, Any]:
    gaps = grid.start_x_m[1:] > grid.end_x_m[:-1]
    if gaps.any():
        raise ValueError(f"corridor {grid.corridor_id}: sub-segments must be contiguous")
    return {
        "corridor": grid.corridor_id,
        "window_start": window_start,
        "window_end": window_end,
        "starts": grid.start_x_m.tolist(),
        "segment_ids": grid.segment_ids.tolist(),
        "first_start": float(grid.start_x_m[0]),
        "last_end": float(grid.end_x_m[-1]),
        "lanes": grid.lanes,
        "engaged_pings": engaged_pings,
    }


def _ping_window(rows: Sequence[Row[Any]]) -> PingWindow:
    """Pooled rows (lane, 1-based cell, ...) plus the totals row and the off-corridor row."""
    cells = [row for row in rows if row.lane is not None]
    totals = next((row for row in rows if row.lane is None and row.cell is None), None)
    off = next((row for row in rows if row.cell == -1), None)
    set_aside = next((row for row in rows if row.cell == -2), None)
    observations = LaneObservations(
        lane=np.array([row.lane for row in cells], dtype=np.int64),
        cell=np.array([row.cell - 1 for row in cells], dtype=np.int64),
        mean_speed_mps=np.array([row.mean_speed_mps for row in cells], dtype=np.float64),
        ping_count=np.array([row.ping_count for row in cells], dtype=np.int64),
    )
    return PingWindow(
        observations=observations,
        vehicles=int(totals.vehicles or 0) if totals is not None else 0,
        pings=int(totals.ping_count or 0) if totals is not None else 0,
        pings_off_corridor=int(off.ping_count or 0) if off is not None else 0,
        pings_set_aside=int(set_aside.ping_count or 0) if set_aside is not None else 0,
    )


def pool_pings(
    session: Session,
    grid: CorridorGrid,
    window_start: datetime,
    window_end: datetime,
    engaged_pings: EngagedPings,
) -> PingWindow:
    """The fleet's speeds per lane and sub-segment in the window, straight from the pings.

    Pings off the corridor (x_m NULL) or in a lane the corridor lacks do not feed the TSE; a
    ping without a lane counts in its vehicle's assigned lane. Pings the `engaged_pings` rule
    sets aside (an engaged car with no leader in radar range) feed nothing and are counted.
    """
    params = _window_params(grid, window_start, window_end, engaged_pings)
    return _ping_window(session.execute(POOL_PINGS, params).all())


def store_observations(
    session: Session, grid: CorridorGrid, window_start: datetime, window_end: datetime
) -> int:
    """Write each vehicle's mean speed per sub-segment and lane in the window (paper:
    fact_vehicle_observation); returns the rows written. The fact keeps every vehicle's speed,
    whatever the cycle's `engaged_pings` rule fused."""
    result = session.execute(
        STORE_OBSERVATIONS, _window_params(grid, window_start, window_end, "all")
    )
    return int(result.rowcount)  # type: ignore[attr-defined]


def stored_observations(session: Session, grid: CorridorGrid, window_end: datetime) -> PingWindow:
    """The window's observations as stored, pooled per lane and sub-segment."""
    rows = session.execute(
        POOLED_OBSERVATIONS,
        {
            "corridor": grid.corridor_id,
            "window_end": window_end,
            "segment_ids": grid.segment_ids.tolist(),
        },
    ).all()
    return _ping_window(rows)


def load_smoothed(session: Session, grid: CorridorGrid, plan_ids: list[int]) -> list[FloatArray]:
    """The stored smoothed lane profiles of the given plans, in the given order."""
    if not plan_ids:
        return []
    rows = session.execute(
        text(
            "SELECT plan_id, lane, i24_segment_id, smoothed_speed_mps FROM fact_speed_planner "
            "WHERE corridor_id = :corridor AND plan_id = ANY(:plan_ids)"
        ),
        {"corridor": grid.corridor_id, "plan_ids": plan_ids},
    ).all()
    cell_of_segment = {int(segment): cell for cell, segment in enumerate(grid.segment_ids)}
    profiles = {plan_id: np.full((grid.lanes, grid.cells), np.nan) for plan_id in plan_ids}
    for row in rows:
        cell = cell_of_segment.get(row.i24_segment_id)
        if cell is not None and 1 <= row.lane <= grid.lanes and row.smoothed_speed_mps is not None:
            profiles[row.plan_id][row.lane - 1, cell] = row.smoothed_speed_mps
    # A plan made on another grid (the corridor was re-seeded since) cannot be compared.
    return [profiles[plan_id] for plan_id in plan_ids if np.isfinite(profiles[plan_id]).all()]


def recent_plan_ids(
    session: Session, corridor_id: str, now: datetime, params: PlannerParams
) -> list[int]:
    """The published plans of the last `standing_cycles - 1` cycles before `now`, newest first."""
    since = now - timedelta(seconds=(params.standing_cycles - 0.5) * params.cycle_period_s)
    return list(
        session.scalars(
            text(
                "SELECT plan_id FROM plan_run WHERE corridor_id = :corridor "
                "AND status = 'published' AND started_at < :now AND started_at > :since "
                "ORDER BY started_at DESC LIMIT :limit"
            ),
            {
                "corridor": corridor_id,
                "now": now,
                "since": since,
                "limit": params.standing_cycles - 1,
            },
        )
    )


def _try_lock(session: Session, corridor_id: str) -> bool:
    return bool(
        session.scalar(
            text("SELECT pg_try_advisory_xact_lock(:space, hashtext(:corridor))"),
            {"space": PLANNER_LOCK_SPACE, "corridor": corridor_id},
        )
    )


def _window_taken_since(session: Session, corridor_id: str, since: datetime) -> bool:
    """Whether a cycle since `since` published a plan or was skipped: both store their ping
    window's observations, so a second replica's cycle moments later would store the same pings
    again (a skipped run was not counted before 2026-12-05, and with INRIX down two replicas
    each stored every window)."""
    return bool(
        session.scalar(
            text(
                "SELECT EXISTS (SELECT 1 FROM plan_run WHERE corridor_id = :corridor "
                "AND status IN ('published', 'skipped') AND started_at > :since)"
            ),
            {"corridor": corridor_id, "since": since},
        )
    )


def _insert_run(
    session: Session,
    corridor_id: str,
    *,
    status: str,
    reason: str | None,
    algorithm: str,
    params: dict[str, Any],
    inputs: dict[str, Any],
    started_at: datetime,
    published_at: datetime | None,
    valid_until: datetime | None,
    duration_ms: float,
) -> int:
    plan_id = session.scalar(
        text(
            "INSERT INTO plan_run (corridor_id, status, reason, algorithm, params, inputs, "
            "started_at, published_at, valid_until, duration_ms) VALUES (:corridor, :status, "
            ":reason, :algorithm, CAST(:params AS jsonb), CAST(:inputs AS jsonb), :started_at, "
            ":published_at, :valid_until, :duration_ms) RETURNING plan_id"
        ),
        {
            "corridor": corridor_id,
            "status": status,
            "reason": reason,
            "algorithm": algorithm,
            "params": _json(params),
            "inputs": _json(inputs),
            "started_at": started_at,
            "published_at": published_at,
            "valid_until": valid_until,
            "duration_ms": duration_ms,
        },
    )
    return int(plan_id)


def _json(value: dict[str, Any]) -> str:
    return json.dumps(value, allow_nan=False)


INSERT_PLAN_ROWS = text(
    """
    INSERT INTO fact_speed_planner
        (corridor_id, plan_id, lane, i24_segment_id, target_speed_mps, is_buffer,
         tse_speed_mps, smoothed_speed_mps, fleet_speed_mps, fleet_ping_count)
    SELECT :corridor, :plan_id, lane, segment, target, buffer, tse, smoothed, fleet, fleet_pings
    FROM unnest(CAST(:lanes AS smallint[]), CAST(:segments AS integer[]),
                CAST(:targets AS real[]), CAST(:buffers AS boolean[]),
                CAST(:tses AS real[]), CAST(:smootheds AS real[]),
                CAST(:fleet AS float8[]), CAST(:fleet_pings AS integer[]))
         AS rows (lane, segment, target, buffer, tse, smoothed, fleet, fleet_pings)
    """
)

# inputs["fleet_observations"] of a plan whose rows hold the fleet observation it read.
FLEET_IN_PLAN_ROWS = "plan_rows"


def _fleet_cells(
    grid: CorridorGrid, observations: LaneObservations
) -> tuple[list[float | None], list[int | None]]:
    """The observation of each plan cell (lane-major, as the plan rows), None where none.

    The warehouse pools the window per lane and sub-segment, so each cell has one row at most;
    its mean is stored as read, so a replay hands the planner the very same numbers.
    """
    speeds: list[float | None] = [None] * (grid.lanes * grid.cells)
    counts: list[int | None] = [None] * (grid.lanes * grid.cells)
    for lane, cell, speed, count in zip(
        observations.lane.tolist(),
        observations.cell.tolist(),
        observations.mean_speed_mps.tolist(),
        observations.ping_count.tolist(),
        strict=True,
    ):
        position = (lane - 1) * grid.cells + cell
        if counts[position] is not None:
            raise ValueError(f"observations: lane {lane}, cell {cell} appears twice")
        speeds[position] = speed
        counts[position] = count
    return speeds, counts


def _publish_rows(
    session: Session, grid: CorridorGrid, plan_id: int, plan: Plan, fleet: LaneObservations
) -> None:
    lanes = np.repeat(np.arange(1, grid.lanes + 1), grid.cells)
    segments = np.tile(grid.segment_ids, grid.lanes)
    fleet_speeds, fleet_pings = _fleet_cells(grid, fleet)
    session.execute(
        INSERT_PLAN_ROWS,
        {
            "corridor": grid.corridor_id,
            "plan_id": plan_id,
            "lanes": lanes.tolist(),
            "segments": segments.tolist(),
            "targets": plan.target_mps.ravel().tolist(),
            "buffers": plan.is_buffer.ravel().tolist(),
            "tses": plan.tse_mps.ravel().tolist(),
            "smootheds": plan.smoothed_mps.ravel().tolist(),
            "fleet": fleet_speeds,
            "fleet_pings": fleet_pings,
        },
    )


def _stored_fleet(session: Session, grid: CorridorGrid, plan_id: int) -> LaneObservations:
    """The fleet observation a plan read, from its own rows (FLEET_IN_PLAN_ROWS)."""
    rows = session.execute(
        text(
            "SELECT lane, i24_segment_id, fleet_speed_mps, fleet_ping_count "
            "FROM fact_speed_planner WHERE corridor_id = :corridor AND plan_id = :plan_id "
            "AND fleet_ping_count IS NOT NULL"
        ),
        {"corridor": grid.corridor_id, "plan_id": plan_id},
    ).all()
    cell_of_segment = {int(segment): cell for cell, segment in enumerate(grid.segment_ids)}
    return LaneObservations(
        lane=np.array([row.lane for row in rows], dtype=np.int64),
        cell=np.array([cell_of_segment[row.i24_segment_id] for row in rows], dtype=np.int64),
        mean_speed_mps=np.array([row.fleet_speed_mps for row in rows], dtype=np.float64),
        ping_count=np.array([row.fleet_ping_count for row in rows], dtype=np.int64),
    )


def store_window_observations(session: Session, outcome: CycleOutcome) -> int:
    """Write the per-vehicle observations of a published or skipped cycle's ping window."""
    if outcome.status not in ("published", "skipped"):
        return 0
    grid = load_grid(session, outcome.corridor_id)
    return store_observations(
        session,
        grid,
        datetime.fromisoformat(outcome.inputs["ping_window_start"]),
        datetime.fromisoformat(outcome.inputs["ping_window_end"]),
    )


def run_cycle(
    session: Session,
    corridor_id: str,
    *,
    algorithm: str,
    params: PlannerParams,
    valid_for_s: float,
    now: datetime | None = None,
    min_interval_s: float = 0.0,
) -> CycleOutcome:
    """One planner cycle for one corridor in the caller's transaction (steps 1-6).

    Returns `busy` without writing when another planner holds the corridor or published less
    than `min_interval_s` ago (or was skipped then: either stored its ping window); `skipped`
    (with a plan_run row saying why) when there is no estimate; `published` otherwise. Any
    other error propagates: the caller rolls back and records the failure (`record_failure`).
    """
    clock = time.perf_counter()
    now = now or datetime.now(UTC)
    if now.tzinfo is None:
        raise ValueError("run_cycle: `now` must carry a time zone")
    if not _try_lock(session, corridor_id):
        return CycleOutcome(corridor_id, "busy", reason="another planner holds this corridor")
    if min_interval_s > 0 and _window_taken_since(
        session, corridor_id, now - timedelta(seconds=min_interval_s)
    ):
        return CycleOutcome(corridor_id, "busy", reason="a cycle ran moments ago")
    grid = load_grid(session, corridor_id)
    inrix = load_inrix(session, corridor_id, now, params, received_by=now)
    window_start = now - timedelta(seconds=params.ping_window_s)
    pings = pool_pings(session, grid, window_start, now, params.engaged_pings)
    previous = recent_plan_ids(session, corridor_id, now, params)
    inputs: dict[str, Any] = {
        "inrix_as_of": None,
        "inrix_age_s": None,
        "inrix_oldest_reading_age_s": None,
        "inrix_snapshots": inrix.history.snapshots,
        "inrix_history_start": _iso(now - timedelta(seconds=params.inrix_history_s)),
        "inrix_received_by": _iso(now),
        "inrix_ignored": inrix.ignored,
        "ping_window_start": _iso(window_start),
        "ping_window_end": _iso(now),
        "vehicles": pings.vehicles,
        "pings": pings.pings,
        "pings_off_corridor": pings.pings_off_corridor,
        "pings_set_aside": pings.pings_set_aside,
        "previous_plans": previous,
        # Exactly which INRIX snapshots the cycle read: one committing just after the read,
        # with received_at before it, must not enter a replay.
        "inrix_measured_at": [_iso(moment) for moment in inrix.measured_at],
        # ... and, of those, the segments without a reading then: one of them committing
        # after the read, received before it, must not enter a replay either.
        "inrix_segments_unread": {_iso(moment): codes for moment, codes in inrix.unread.items()},
        "fleet_observations": FLEET_IN_PLAN_ROWS,
    }
    planner_inputs = PlannerInputs(
        grid,
        inrix.history,
        pings.observations,
        _epoch_s(now),
        tuple(load_smoothed(session, grid, previous)),
    )
    try:
        plan = plan_speeds(planner_inputs, algorithm, params)
    except NoInrixEstimate as error:
        reason = f"{error}; {pings.pings} pings from {pings.vehicles} vehicles in the window"
        duration_ms = (time.perf_counter() - clock) * 1000
        plan_id = _insert_run(
            session,
            corridor_id,
            status="skipped",
            reason=reason,
            algorithm=algorithm,
            params=params.stored(),
            inputs=inputs,
            started_at=now,
            published_at=None,
            valid_until=None,
            duration_ms=duration_ms,
        )
        return CycleOutcome(corridor_id, "skipped", plan_id, reason, duration_ms, inputs)
    as_of = datetime.fromtimestamp(plan.inrix_as_of_s, UTC)
    inputs["inrix_as_of"] = _iso(as_of)
    inputs["inrix_age_s"] = round((now - as_of).total_seconds(), 3)
    # a partial outage: segments the newest snapshot did not read stand on older readings
    oldest = datetime.fromtimestamp(plan.inrix_oldest_used_s, UTC)
    inputs["inrix_oldest_reading_age_s"] = round((now - oldest).total_seconds(), 3)
    duration_ms = (time.perf_counter() - clock) * 1000
    published_at = now + timedelta(milliseconds=duration_ms)
    plan_id = _insert_run(
        session,
        corridor_id,
        status="published",
        reason=None,
        algorithm=algorithm,
        params=params.stored(),
        inputs=inputs,
        started_at=now,
        published_at=published_at,
        valid_until=published_at + timedelta(seconds=valid_for_s),
        duration_ms=duration_ms,
    )
    _publish_rows(session, grid, plan_id, plan, pings.observations)
    return CycleOutcome(corridor_id, "published", plan_id, None, duration_ms, inputs)


def record_failure(
    session: Session,
    corridor_id: str,
    *,
    algorithm: str,
    params: PlannerParams,
    started_at: datetime,
    reason: str,
) -> int:
    """A plan_run row saying a cycle failed and why (the last good plan simply ages out)."""
    duration_ms = (datetime.now(UTC) - started_at).total_seconds() * 1000
    return _insert_run(
        session,
        corridor_id,
        status="failed",
        reason=reason[:2000],
        algorithm=algorithm,
        params=params.stored(),
        inputs={},
        started_at=started_at,
        published_at=None,
        valid_until=None,
        duration_ms=max(0.0, duration_ms),
    )


def replay_plan(session: Session, plan_id: int) -> ReplayReport:
    """Recompute a published plan from the warehouse and compare it with what was stored."""
    run = (
        session.execute(
            text(
                "SELECT corridor_id, status, algorithm, params, inputs, started_at "
                "FROM plan_run WHERE plan_id = :plan_id"
            ),
            {"plan_id": plan_id},
        )
        .mappings()
        .first()
    )
    if run is None:
        raise UnknownPlan(f"no plan {plan_id}")
    if run["status"] != "published":
        raise UnknownPlan(f"plan {plan_id} was {run['status']}, not published: nothing to replay")
    # A plan stored before `min_inrix_score` existed read every score.
    params = PlannerParams.parse({"min_inrix_score": 0, **run["params"]})
    inputs = run["inputs"]
    now: datetime = run["started_at"]
    grid = load_grid(session, run["corridor_id"])
    inrix = load_inrix(
        session,
        run["corridor_id"],
        now,
        params,
        received_by=datetime.fromisoformat(inputs["inrix_received_by"]),
        measured_at=(
            None
            if "inrix_measured_at" not in inputs
            else {datetime.fromisoformat(moment) for moment in inputs["inrix_measured_at"]}
        ),
        unread=(
            None  # a plan stored before 2026-12-05: a reading committed late may enter
            if "inrix_segments_unread" not in inputs
            else {
                datetime.fromisoformat(moment): set(codes)
                for moment, codes in inputs["inrix_segments_unread"].items()
            }
        ),
    )
    window_start = datetime.fromisoformat(inputs["ping_window_start"])
    window_end = datetime.fromisoformat(inputs["ping_window_end"])
    if inputs.get("fleet_observations") == FLEET_IN_PLAN_ROWS:
        fleet = _stored_fleet(session, grid, plan_id)
    else:  # a plan stored before its rows kept the observation: the best record left
        pings = stored_observations(session, grid, window_end)
        if pings.pings != inputs["pings"]:
            # The observations are written just after publication; if that failed, the pings
            # themselves (still within retention) are the record.
            pings = pool_pings(session, grid, window_start, window_end, params.engaged_pings)
        fleet = pings.observations
    previous = [int(plan) for plan in inputs.get("previous_plans", [])]
    plan = plan_speeds(
        PlannerInputs(
            grid,
            inrix.history,
            fleet,
            _epoch_s(now),
            tuple(load_smoothed(session, grid, previous)),
        ),
        run["algorithm"],
        params,
    )
    stored = session.execute(
        text(
            "SELECT lane, i24_segment_id, target_speed_mps, is_buffer FROM fact_speed_planner "
            "WHERE corridor_id = :corridor AND plan_id = :plan_id"
        ),
        {"corridor": run["corridor_id"], "plan_id": plan_id},
    ).all()
    cell_of_segment = {int(segment): cell for cell, segment in enumerate(grid.segment_ids)}
    difference = 0.0
    buffers_differing = 0
    for row in stored:
        cell = cell_of_segment[row.i24_segment_id]
        # Both as the REAL column holds them: the driver hands a REAL back as its shortest
        # decimal (28.999998), which is the float32 28.999998092651367 only once re-rounded.
        recomputed = np.float32(plan.target_mps[row.lane - 1, cell])
        stored_target = np.float32(row.target_speed_mps)
        difference = max(difference, abs(float(recomputed) - float(stored_target)))
        buffers_differing += int(bool(plan.is_buffer[row.lane - 1, cell]) != row.is_buffer)
    missing = grid.lanes * grid.cells - len(stored)
    return ReplayReport(
        plan_id=plan_id,
        corridor_id=run["corridor_id"],
        algorithm=run["algorithm"],
        cells=len(stored),
        max_difference_mps=difference if missing == 0 else float("inf"),
        buffer_cells_differing=buffers_differing,
    )
