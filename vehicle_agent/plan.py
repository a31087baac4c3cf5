"""Plans as the agent holds them: validated on arrival, looked up at the car's position.

The document is the contract's (`contract.plans.PlanTargets`, the fields of the server's
`PlanOut` a car reads). A plan lane gives target speeds per sub-segment, `target_speed_mps[i]`
holding from `x_m[i]` to `end_x_m[i]`. A plan that could make the car misbehave is refused
whole: no lanes, arrays of different lengths, positions not increasing, a speed that is
negative or not finite. The agent then has no fresh plan and leaves the car to its stock ACC.
"""

from __future__ import annotations

import math
from datetime import datetime

import numpy as np
from pydantic import Field, ValidationError, model_validator

from contract.plans import LaneTargets, PlanTargets
from contract.units import WAVE_SPEED_MPS
from contract.values import first_problem
from vehicle_agent.controllers import TargetProfile

# Waves travel upstream at about this speed (m/s; negative = upstream): 15 km/h, the speed the
# Speed Planner's INRIX prediction assumes (planner/params.py), so a plan is aged the way it was
# made. Plan lookups move downstream by it x the plan's age.
DEFAULT_WAVE_SPEED_MPS = -WAVE_SPEED_MPS

# Fastest plausible target (m/s, about 134 mph): anything above is garbage.
MAX_TARGET_SPEED_MPS = 60.0
# Sub-segment steps are drawn this far (m) before the next segment starts, so np.interp sees
# strictly increasing positions.
STEP_EDGE_M = 0.01
# How far past a lane's first or last point the car may be and still take the plan's target
# there: about a GPS fix's and the map-matching's error. Further out the lookup would hold the
# end's target flat, a speed the plan never set for the car's place.
PLAN_REACH_TOLERANCE_M = 50.0


class PlanError(ValueError):
    """A plan the agent refuses; the message says what was wrong."""


class PlanLane(LaneTargets):
    """One lane's targets along the corridor, checked as the car needs them."""

    @model_validator(mode="after")
    def _consistent(self) -> PlanLane:
        n = len(self.x_m)
        if n == 0 or len(self.target_speed_mps) != n:
            raise ValueError(
                f"lane {self.lane}: {n} positions but {len(self.target_speed_mps)} speeds"
            )
        if len(self.end_x_m) != n:
            raise ValueError(f"lane {self.lane}: {n} positions but {len(self.end_x_m)} ends")
        values = [*self.x_m, *self.end_x_m]
        if not all(math.isfinite(v) for v in values):
            raise ValueError(f"lane {self.lane}: a position is not finite")
        if any(b <= a for a, b in zip(self.x_m, self.x_m[1:], strict=False)):
            raise ValueError(f"lane {self.lane}: positions do not increase")
        if any(end <= start for start, end in zip(self.x_m, self.end_x_m, strict=True)):
            raise ValueError(f"lane {self.lane}: a sub-segment ends before it starts")
        for speed in self.target_speed_mps:
            if not math.isfinite(speed) or speed < 0 or speed > MAX_TARGET_SPEED_MPS:
                raise ValueError(f"lane {self.lane}: target speed {speed} m/s is not usable")
        return self

    def profile_points(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions and speeds for linear lookup (steps drawn as flat runs)."""
        speeds = np.asarray(self.target_speed_mps, dtype=np.float64)
        starts = np.asarray(self.x_m, dtype=np.float64)
        ends = np.asarray(self.end_x_m, dtype=np.float64)
        inner_ends = np.maximum(
            np.minimum(ends, np.append(starts[1:], np.inf)) - STEP_EDGE_M, starts + STEP_EDGE_M / 2
        )
        x = np.column_stack([starts, inner_ends]).ravel()
        return x, np.repeat(speeds, 2)


class Plan(PlanTargets):
    """A published plan (the fields the agent uses; the rest is ignored)."""

    lanes: list[PlanLane] = Field(min_length=1)

    def lane(self, lane: int) -> PlanLane | None:
        """The lane's targets, or None when the plan has no such lane."""
        return next((candidate for candidate in self.lanes if candidate.lane == lane), None)


def parse_plan(body: bytes | str) -> Plan:
    """A validated plan from the server's JSON, or PlanError naming the problem."""
    try:
        return Plan.model_validate_json(body)
    except ValidationError as error:
        raise PlanError(f"plan refused: {first_problem(error)}") from None


class LanePlan:
    """One lane of a plan, ready for lookups, and what the agent knows about its freshness."""

    def __init__(
        self,
        plan: Plan,
        lane: int,
        etag: str | None,
        received_s: float | None = None,
        served_at: datetime | None = None,
    ) -> None:
        lane_plan = plan.lane(lane)
        if lane_plan is None:
            raise PlanError(f"plan {plan.plan_id} has no lane {lane}")
        self.plan = plan
        self.lane = lane
        self.etag = etag
        # The car's monotonic time when the plan arrived: its age by the car's own steady
        # clock, which no wall-clock error or step can make younger.
        self.received_s = received_s
        # How old the plan was when the server sent it, by the server's own clock (its answer's
        # Date less published_at, 0 when unknown): counted on from arrival by the steady clock,
        # the age a car's clock behind the server's cannot take away.
        self.age_when_served_s = (
            0.0 if served_at is None else max((served_at - plan.published_at).total_seconds(), 0.0)
        )
        self.x_m, self.speeds = lane_plan.profile_points()

    @property
    def plan_id(self) -> int:
        """The plan being followed."""
        return self.plan.plan_id

    def age_s(self, wall: datetime, now_s: float | None = None) -> float:
        """Seconds since the plan was published, by the car's wall clock; given the monotonic
        `now_s`, at least its age when the server sent it plus the seconds since it arrived.
        A car whose clock runs behind the server's (a Pi without a real-time clock after boot)
        or steps back would otherwise take an old plan for a young one: with the time since
        arrival alone, a plan served 150 s old was followed 150 s past its validity."""
        age = (wall - self.plan.published_at).total_seconds()
        if now_s is not None and self.received_s is not None:
            age = max(age, self.age_when_served_s + now_s - self.received_s)
        return age

    def reaches(self, x_m: float, shift_m: float = 0.0) -> bool:
        """Whether the lane's targets cover where the car's target is read: its position `x_m`
        moved downstream by the lookup's `shift_m` (`lookup_shift_m`), within
        `PLAN_REACH_TOLERANCE_M` of their ends. A plan for a stretch the car is not on is no
        plan for the car, however fresh; nor is an aged one whose lookup runs past its end,
        which would read the end's target held flat."""
        lookup_m = x_m + shift_m
        return (
            float(self.x_m[0]) - PLAN_REACH_TOLERANCE_M
            <= lookup_m
            <= float(self.x_m[-1]) + PLAN_REACH_TOLERANCE_M
        )

    def is_fresh(self, wall: datetime, stale_after_s: float, now_s: float | None = None) -> bool:
        """Before its own valid_until and published within `stale_after_s`, both judged by its
        age (`age_s`): a wall clock behind the server's keeps a plan no longer after it arrived
        than its publisher said it holds (valid_until less published_at).

        Whether the server could be reached since does not matter: a plan stays right for as
        long as its publisher said, so a server restart or a network gap does not end it.
        """
        age = self.age_s(wall, now_s)
        if age > (self.plan.valid_until - self.plan.published_at).total_seconds():
            return False
        return age <= stale_after_s

    def lookup_shift_m(
        self, wall: datetime, wave_speed_mps: float, now_s: float | None = None
    ) -> float:
        """How far downstream the targets are read now: -wave speed x plan age (the waves the
        plan describes have travelled upstream since it was published)."""
        return -wave_speed_mps * max(self.age_s(wall, now_s), 0.0)

    def profile(
        self, wall: datetime, wave_speed_mps: float, now_s: float | None = None
    ) -> TargetProfile:
        """Targets as seen now: the lookup moves downstream by `lookup_shift_m`."""
        return TargetProfile(
            self.x_m, self.speeds, shift_m=self.lookup_shift_m(wall, wave_speed_mps, now_s)
        )
