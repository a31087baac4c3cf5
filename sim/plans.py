"""The Speed Planner in the simulation loop, run as the server runs it.

Every `period_s` (60 s) of simulated time the real planner (`planner.plan_speeds`, the same
registered algorithm and parameters as the server's) is fed what the server would have: the
INRIX minutes it has received by then (simulated by `sim.inrix` with the real feed's errors and
lag, or the drive's real minutes) and the fleet's pings of the last ping window (the simulated
AVs post one per second, like the agent).
Each plan is handed to the AVs as the agent receives it (a `vehicle_agent.plan.Plan`, sub-segment
steps with their ends) and read with the agent's own `LanePlan.profile`: the lookup shifted by
the agent's wave speed times the plan's age.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contract.vehicles import STALE_PLAN_AFTER_S
from planner import (
    CorridorGrid,
    InrixHistory,
    LaneObservations,
    NoInrixEstimate,
    PlannerInputs,
    PlannerParams,
    parse_params,
    plan_speeds,
)
from planner.inputs import traffic_pings
from sim.drives import Drive
from sim.inrix import CALIBRATED, simulated_feed
from sim.traffic import INRIX_PERIOD_S, InrixFeed, segment_bounds
from vehicle_agent.controllers import TargetProfile
from vehicle_agent.plan import DEFAULT_WAVE_SPEED_MPS, LanePlan, Plan, PlanLane

FloatArray = NDArray[np.float64]

PLANNER_PERIOD_S = 60.0
# The simulated road: sub-segments of 100 m (as the seed corridor's), one lane (a platoon), and
# the seed corridor's legal target range (70 mph limit, 20 mph lowest target).
CELL_M = 100.0
SIM_LANE = 1
SPEED_LIMIT_MPS = 31.2928
MIN_TARGET_SPEED_MPS = 8.9408
# The road simulated reaches this far behind the drive's start (the platoon's tail starts up to
# ~1.6 km back) and this far past its end (the smoothing window looks ahead up to 2 km).
ROAD_BEFORE_M = 3000.0
ROAD_AFTER_M = 3000.0


def simulated_grid(drive: Drive) -> CorridorGrid:
    """The planner's sub-segments along the simulated road (the drive's own frame)."""
    start = -ROAD_BEFORE_M
    end = float(drive.position_m[-1]) + ROAD_AFTER_M
    edges = np.arange(start, end + CELL_M, CELL_M)
    return CorridorGrid(
        corridor_id=f"sim:{drive.name}",
        lanes=1,
        start_x_m=edges[:-1],
        end_x_m=edges[1:],
        segment_ids=np.arange(1, len(edges), dtype=np.int64),
        speed_limit_mps=SPEED_LIMIT_MPS,
        min_target_speed_mps=MIN_TARGET_SPEED_MPS,
    )


def simulated_inrix(drive: Drive, params: PlannerParams) -> InrixFeed:
    """The drive's simulated INRIX (`sim.inrix`, calibrated on the real feed; seeded by the
    drive's name): a reading a minute per 0.5 mile segment, from a history window before the
    drive to its end."""
    bounds = segment_bounds(-ROAD_BEFORE_M, float(drive.position_m[-1]) + ROAD_AFTER_M)
    first = -math.ceil((params.inrix_history_s + INRIX_PERIOD_S) / INRIX_PERIOD_S) * INRIX_PERIOD_S
    stamps = np.arange(first, drive.duration_s + 1e-9, INRIX_PERIOD_S)
    return simulated_feed(drive, bounds, stamps, CALIBRATED)


class NoPlanHeld(ValueError):
    """The AVs hold no fresh plan at this time (`SimulatedPlanner.profile` is None), where the
    caller needs one: a study or a training window on simulated INRIX, which always has one."""


@dataclass
class SimulatedPlanner:
    """One corridor's planner schedule over simulated time; the AVs share it."""

    algorithm: str
    params: PlannerParams
    grid: CorridorGrid
    feed: InrixFeed
    period_s: float = PLANNER_PERIOD_S
    plans_run: int = 0
    # Plans that held a buffer (a standing bottleneck's deceleration region).
    plans_buffered: int = 0
    # Cycles without INRIX: skipped, as the server skips them; the AVs keep the last plan while
    # it is fresh (`STALE_PLAN_AFTER_S`), then drive on their stock ACC (`sim.av`).
    plans_skipped: int = 0
    _ping_time: list[float] = field(default_factory=list)
    _ping_x: list[float] = field(default_factory=list)
    _ping_speed: list[float] = field(default_factory=list)
    _ping_engaged: list[bool] = field(default_factory=list)
    _ping_lead: list[bool] = field(default_factory=list)
    _previous_smoothed: deque[FloatArray] = field(default_factory=deque)
    # Simulated time 0 on the plans' clock (plans carry wall-clock publication times).
    epoch: datetime = datetime(2021, 1, 1, tzinfo=UTC)
    _lane_plan: LanePlan | None = None
    _next_cycle_s: float = -math.inf
    # The last lookup, for the platoon's other AVs asking at the same step (each would repeat
    # the same datetime arithmetic and build the same profile).
    _looked_up: tuple[float, TargetProfile | None] | None = None

    @classmethod
    def for_drive(
        cls,
        drive: Drive,
        algorithm: str,
        params: Mapping[str, Any] | None = None,
        feed: InrixFeed | None = None,
    ) -> SimulatedPlanner:
        """A planner over the drive's road, with validated parameters, reading `feed` (the real
        INRIX of the drive) or INRIX simulated from the drive."""
        checked = parse_params(params)
        inrix = feed if feed is not None else simulated_inrix(drive, checked)
        return cls(algorithm, checked, simulated_grid(drive), inrix)

    def record_ping(
        self, time_s: float, x_m: float, speed_mps: float, *, engaged: bool, lead_present: bool
    ) -> None:
        """An AV's ping (the agent posts one per second), with its controller's engagement and
        its radar's lead flag as the ping carries them."""
        self._ping_time.append(time_s)
        self._ping_x.append(x_m)
        self._ping_speed.append(speed_mps)
        self._ping_engaged.append(engaged)
        self._ping_lead.append(lead_present)

    def profile(self, time_s: float) -> TargetProfile | None:
        """The plan the AVs hold at `time_s`, looked up as the agent does; None while they hold
        none fresh (the agent's `LanePlan.is_fresh`): before the first plan, or once the last
        was published more than `STALE_PLAN_AFTER_S` ago, when the feed has stopped."""
        if self._looked_up is not None and self._looked_up[0] == time_s:
            return self._looked_up[1]
        if time_s >= self._next_cycle_s:
            cycle_s = math.floor(time_s / self.period_s) * self.period_s
            self._run(cycle_s)
            self._next_cycle_s = cycle_s + self.period_s
        wall = self.epoch + timedelta(seconds=time_s)
        profile = None
        if self._lane_plan is not None and self._lane_plan.is_fresh(wall, STALE_PLAN_AFTER_S):
            profile = self._lane_plan.profile(wall, DEFAULT_WAVE_SPEED_MPS)
        self._looked_up = (time_s, profile)
        return profile

    def held_profile(self, time_s: float) -> TargetProfile:
        """`profile`, for a caller that cannot go on without a plan (`NoPlanHeld` if none)."""
        profile = self.profile(time_s)
        if profile is None:
            raise NoPlanHeld(
                f"{self.grid.corridor_id.removeprefix('sim:')}: no fresh plan at {time_s:.0f} s "
                f"({self.plans_run} published, {self.plans_skipped} cycles without INRIX)"
            )
        return profile

    def _run(self, now_s: float) -> None:
        visible = self.feed.visible_rows(now_s)
        history = InrixHistory(
            self.feed.measured_at_s[visible],
            self.feed.speed_mps[visible],
            self.feed.segment_center_x_m,
        )
        times = np.asarray(self._ping_time)
        window = (
            (times > now_s - self.params.ping_window_s)
            & (times <= now_s)
            & traffic_pings(self._ping_engaged, self._ping_lead, self.params.engaged_pings)
        )
        observations = LaneObservations.from_pings(
            self.grid,
            np.full(int(window.sum()), SIM_LANE),
            np.asarray(self._ping_x)[window],
            np.asarray(self._ping_speed)[window],
        )
        try:
            plan = plan_speeds(
                PlannerInputs(
                    self.grid, history, observations, now_s, tuple(self._previous_smoothed)
                ),
                self.algorithm,
                self.params,
            )
        except NoInrixEstimate:
            # as the server: nothing is published; the AVs hold the last plan while it is fresh
            self.plans_skipped += 1
            return
        self._previous_smoothed.appendleft(plan.smoothed_mps)
        while len(self._previous_smoothed) > self.params.standing_cycles:
            self._previous_smoothed.pop()
        published = self.epoch + timedelta(seconds=now_s)
        agent_plan = Plan(
            plan_id=self.plans_run + 1,
            corridor=self.grid.corridor_id,
            published_at=published,
            # as the server's default (`plan_valid_for_s`): the car's limit decides first
            valid_until=published + timedelta(seconds=STALE_PLAN_AFTER_S),
            lanes=[
                PlanLane(
                    lane=SIM_LANE,
                    x_m=self.grid.start_x_m.tolist(),
                    end_x_m=self.grid.end_x_m.tolist(),
                    target_speed_mps=plan.target_mps[SIM_LANE - 1].tolist(),
                )
            ],
        )
        self._lane_plan = LanePlan(agent_plan, SIM_LANE, None)
        self.plans_run += 1
        self.plans_buffered += int(bool(plan.is_buffer.any()))
