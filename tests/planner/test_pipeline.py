"""The six steps over arrays: what the simulator and the warehouse both rely on."""

from __future__ import annotations

import numpy as np
import pytest

from planner import (
    CorridorGrid,
    InrixHistory,
    InvalidParams,
    LaneObservations,
    NoInrixEstimate,
    PlannerInputs,
    PlannerParams,
    UnknownVariant,
    parse_params,
    plan_speeds,
)
from planner.pipeline import STAGE_REGISTRIES, NonFiniteTargets, clip_to_legal_range
from tests.planner.grids import uniform_grid

GRID = uniform_grid(150, lanes=2)  # 15 km, 2 lanes
CENTERS = np.arange(500.0, 15000.0, 1000.0)  # 15 INRIX segments of 1 km


def standing_jam_history(now_s: float) -> InrixHistory:
    """Five minutes of INRIX with the same jam at 9-10 km (segment 10)."""
    speeds = np.full((5, 15), 30.0)
    speeds[:, 9] = 6.0
    return InrixHistory(now_s - 60.0 * np.arange(5, 0, -1), speeds, CENTERS)


def cycles(count: int, algorithm: str, grid: CorridorGrid = GRID) -> list:
    """Run `count` planner cycles a minute apart, each remembering the earlier ones."""
    plans: list = []
    for cycle in range(count):
        now_s = 1000.0 + 60.0 * cycle
        previous = tuple(plan.smoothed_mps for plan in reversed(plans))
        inputs = PlannerInputs(
            grid, standing_jam_history(now_s), LaneObservations(), now_s, previous
        )
        plans.append(plan_speeds(inputs, algorithm))
    return plans


def test_kernel_smooth_slows_ahead_of_the_jam_without_buffers() -> None:
    (plan,) = cycles(1, "kernel_smooth")
    target = plan.target_mps[0]
    assert plan.algorithm == "kernel_smooth"
    assert plan.buffers == ()
    assert target[20] == pytest.approx(30.0)  # far upstream: free flow
    assert target[85] < 20.0  # 500 m before the jam the window already holds it
    assert not plan.is_buffer.any()


def test_buffers_appear_only_once_the_bottleneck_has_stood_four_cycles() -> None:
    plans = cycles(5, "kernel_smooth_buffer")
    assert [len(plan.buffers) for plan in plans] == [0, 0, 0, 2, 2]  # one per lane
    last = plans[-1]
    assert last.standing_bottlenecks.sum() == 2
    buffered = last.is_buffer[0]
    assert buffered.any()
    assert not buffered[95:].any()
    assert np.all(last.target_mps[0][buffered] < last.smoothed_mps[0][buffered])
    assert np.all(last.target_mps[0][buffered] >= 0.8 * last.smoothed_mps[0][buffered] - 1e-9)


def test_every_target_is_within_the_legal_range() -> None:
    plan = cycles(5, "kernel_smooth_buffer")[-1]
    assert plan.target_mps.min() >= GRID.min_target_speed_mps  # the jam is 6 m/s, clipped
    assert plan.target_mps.max() <= GRID.speed_limit_mps
    assert plan.tse_mps.min() < GRID.min_target_speed_mps  # the TSE itself is not clipped


@pytest.mark.parametrize("algorithm", ["kernel_smooth", "kernel_smooth_buffer"])
def test_traffic_above_the_limit_is_planned_at_the_limit_plus_the_allowance(algorithm: str) -> None:
    now_s = 1000.0
    history = InrixHistory(now_s - 60.0 * np.arange(5, 0, -1), np.full((5, 15), 33.0), CENTERS)
    inputs = PlannerInputs(GRID, history, LaneObservations(), now_s)
    at_limit = plan_speeds(inputs, algorithm)
    assert at_limit.target_mps.max() == pytest.approx(70 * 0.44704)  # the posted limit
    # The paper's fleet: up to 73 mph on the 70 mph road.
    allowed = plan_speeds(inputs, algorithm, PlannerParams(speed_limit_allowance_mps=3 * 0.44704))
    assert allowed.target_mps.max() == pytest.approx(73 * 0.44704)
    assert allowed.target_mps.min() == pytest.approx(73 * 0.44704)
    assert allowed.params.stored()["speed_limit_allowance_mps"] == pytest.approx(1.34112)
    with pytest.raises(InvalidParams, match="speed_limit_allowance_mps"):
        PlannerParams.parse({"speed_limit_allowance_mps": -1})


def test_fleet_observations_make_the_tse_lane_level() -> None:
    observations = LaneObservations(lane=[2], cell=[40], mean_speed_mps=[12.0], ping_count=[60])
    now_s = 1000.0
    inputs = PlannerInputs(GRID, standing_jam_history(now_s), observations, now_s)
    plan = plan_speeds(inputs, "kernel_smooth")
    assert plan.tse_mps[1, 40] == 12.0
    assert plan.tse_mps[0, 40] > 12.0  # lane 1 only hears of it at half weight


def test_stale_inrix_gives_no_plan() -> None:
    inputs = PlannerInputs(GRID, standing_jam_history(0.0), LaneObservations(), 1000.0)
    with pytest.raises(NoInrixEstimate):
        plan_speeds(inputs)


def test_unknown_algorithm_and_bad_parameters_say_what_was_wrong() -> None:
    inputs = PlannerInputs(GRID, standing_jam_history(1000.0), LaneObservations(), 1000.0)
    with pytest.raises(UnknownVariant, match="kernel_smooth, kernel_smooth_buffer"):
        plan_speeds(inputs, "magic")
    with pytest.raises(UnknownVariant, match="unknown kernel 'box'"):
        plan_speeds(inputs, "kernel_smooth", PlannerParams(kernel="box"))
    with pytest.raises(InvalidParams, match="planner parameter window_m"):
        PlannerParams.parse({"window_m": -5})
    # infinity passed every "greater than 0", and every cycle then planned NaN
    with pytest.raises(InvalidParams, match="planner parameter trend_damping_s"):
        PlannerParams.parse({"trend_damping_s": float("inf")})
    with pytest.raises(NonFiniteTargets, match="1 of the plan's 3 targets are no number"):
        clip_to_legal_range(np.array([10.0, np.nan, 20.0]), GRID, PlannerParams())
    for stage in STAGE_REGISTRIES:
        with pytest.raises(InvalidParams, match=f"planner parameter {stage}: unknown .* 'x'"):
            parse_params({stage: "x"})
    assert parse_params({"kernel": "quartic"}).kernel == "quartic"
    with pytest.raises(InvalidParams, match="planner parameter colour"):
        PlannerParams.parse({"colour": "red"})
    with pytest.raises(InvalidParams, match="standing_required"):
        PlannerParams.parse({"standing_required": 6, "standing_cycles": 5})
    # a buffer at the IDM's desired speed could store no vehicle (density 0): every cycle with
    # a standing queue would divide by zero
    with pytest.raises(InvalidParams, match="buffer_speed_margin_mps .* must be below"):
        PlannerParams.parse({"buffer_speed_margin_mps": 10})
