"""No registered controller, with any parameters the registry accepts, collides (issue 12):

- on a stopped queue behind a stale plan (the issue's crash: 28 m/s, the queue first seen at
  100 m) and behind a leader braking as hard as tyres allow, with the laziest braking each
  parameter model accepts: handed back to the driver, counted as a takeover, nobody collides;
- on every drive of every evaluation scenario (the 32 shared drives, the bottleneck on the
  free-flow ones, and the 9 drives recorded with their real INRIX), every registered controller
  as `smoothfleet sim evaluate` runs it: zero collisions;
- on the most dangerous of those drives (the real-INRIX one whose stale plans hand the car back
  most often), with parameters drawn by hypothesis from each controller's accepted ranges.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import annotated_types
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from contract.controllers import CONTROLLER_SCHEMAS
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.av import agent_policy
from sim.drives import drive_from_speeds, load_drives
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.evaluate import (
    BASELINE,
    ControllerVariant,
    Evaluation,
    default_workers,
    evaluate,
    run_case,
)
from sim.platoon import CutIns, HandBack, platoon_roles, simulate_platoon
from sim.recommended import registered_variants
from sim.recorded import load_recorded_drives
from sim.scenarios import SCENARIOS, Case, scenario_cases
from vehicle_agent.controllers import CONTROLLERS, TargetProfile

# Defaults, and the laziest braking each parameter model accepts.
RECKLESS: dict[str, dict[str, Any]] = {
    "simple": {
        "k": 0.01,
        "min_accel_mps2": -0.1,
        "safety_min_accel_mps2": -0.1,
        "standstill_gap_m": 0.0,
        "lead_min_accel_mps2": -0.1,
        "gap_setting": 1,
    },
    "microaccel": {
        "k": 0.01,
        "min_accel_mps2": -0.1,
        "standstill_gap_m": 0.0,
        "lead_min_accel_mps2": -0.1,
        "k2": 5.0,
        "max_accel_mps2": 4.0,
    },
    "microaccel_acc": {
        "base": {"k": 0.01, "min_accel_mps2": -0.1, "standstill_gap_m": 0.0},
        "acc_response_s": 20.0,
        "congested_gap_setting": 1,
        "free_gap_setting": 1,
    },
}


class StalePlan:
    """The plan the car holds: 28 m/s everywhere, whatever the road ahead does."""

    def profile(self, time_s: float) -> TargetProfile:
        return TargetProfile(np.array([-1e6, 1e6]), np.array([28.0, 28.0]))

    def record_ping(
        self, time_s: float, x_m: float, speed_mps: float, *, engaged: bool, lead_present: bool
    ) -> None:
        pass


def cases() -> list[tuple[str, str, dict[str, Any]]]:
    found = []
    for name, spec in CONTROLLERS.items():
        for actuation in sorted(spec.schema.actuations):
            found.append((name, actuation, {}))
            if name in RECKLESS:
                found.append((name, actuation, RECKLESS[name]))
    return found


def braking(from_mps: float, decel_mps2: float) -> np.ndarray:
    """Speeds at 10 Hz braking constantly from `from_mps` to a stop."""
    return np.arange(from_mps, 0.0, -decel_mps2 * 0.1)


LEADERS = {
    # the leader pulls away at 32 m/s while the stale plan holds the AV at 28; then the queue
    # forms (-4 m/s^2) far ahead of it: the AV's radar first sees it standing at 100 m
    "queue seen at 100 m": np.concatenate([np.full(600, 32.0), braking(32.0, 4.0), np.zeros(600)]),
    # the car ahead brakes as hard as tyres allow, from 28 m/s, the AV close behind
    "hard braking ahead": np.concatenate([np.full(300, 28.0), braking(28.0, 8.0), np.zeros(400)]),
}


@pytest.mark.parametrize("leader", sorted(LEADERS))
@pytest.mark.parametrize(("name", "actuation", "params"), cases())
def test_a_stopped_queue_behind_a_stale_plan(
    name: str, actuation: str, params: dict[str, Any], leader: str
) -> None:
    queue = drive_from_speeds("queue", LEADERS[leader])
    policy = agent_policy(
        name,
        actuation,
        StalePlan(),
        params,
        stock_acc=SimulatedAccCar() if actuation == "acc" else None,
    )
    run = simulate_platoon(
        queue,
        platoon_roles(humans=4, avs=1),
        [policy],
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
        hand_back=HandBack(),
        cut_ins=CutIns(),
    )
    assert run.collisions == 0, run.events
    assert float(np.nanmin(run.gap_m)) > 0.0


# --- every registered controller on every drive -------------------------------------------------


@pytest.fixture(scope="module")
def every_case(shared_dir: Path) -> list[Case]:
    """Every case of every scenario on the shared data (what `sim evaluate` runs by default)."""
    data = shared_dir / "data"
    return scenario_cases(
        list(SCENARIOS),
        load_drives(data / "trajectories"),
        load_recorded_drives(data / "trajectories_with_inrix"),
    )


def collisions_on(cases: list[Case], variant: ControllerVariant, avs: int) -> list[str]:
    """`case: collisions` of every run of the variant with `avs` AVs spread through a platoon
    of 25 followers, under the recommended planner."""
    found = []
    for case in cases:
        result = run_case(
            case,
            RECOMMENDED_PLANNER,
            variant,
            humans=25 - avs,
            avs=avs,
            planner_params=RECOMMENDED_PLANNER_PARAMS,
        )
        if result.kpis.collisions:
            found.append(f"{case.name}: {result.kpis.collisions} collisions")
    return found


@pytest.fixture(scope="module")
def every_registered_run(every_case: list[Case]) -> Evaluation:
    """Every registered controller on every case, as `smoothfleet sim evaluate` runs them: the
    all-human baseline (once per case) and 1 AV behind the leader of 25 followers, under the
    recommended planner, cases side by side on every core."""
    return evaluate(
        every_case,
        [RECOMMENDED_PLANNER],
        registered_variants(),
        planner_params=RECOMMENDED_PLANNER_PARAMS,
        workers=default_workers(),
    )


# The first test to use the sweep pays for all of it (~2 min on two idle cores, several times
# that on a busy machine): beyond the suite's 300 s default.
SWEEP_TIMEOUT_S = 1800


@pytest.mark.slow
@pytest.mark.timeout(SWEEP_TIMEOUT_S)
def test_the_sweep_covers_every_drive_of_every_scenario(
    every_case: list[Case], every_registered_run: Evaluation
) -> None:
    # 20 shockwave + 12 freeflow + 12 bottleneck drives, 7 + 2 recorded with their real INRIX
    counts = {name: sum(case.scenario == name for case in every_case) for name in SCENARIOS}
    assert counts == {
        "shockwave": 20,
        "freeflow": 12,
        "bottleneck": 12,
        "shockwave_inrix": 7,
        "freeflow_inrix": 2,
    }
    runs = (1 + len(registered_variants())) * len(every_case)
    assert len(every_registered_run.results) == runs


@pytest.mark.slow
@pytest.mark.timeout(SWEEP_TIMEOUT_S)
@pytest.mark.parametrize(
    "controller",
    [BASELINE, *(variant.name for variant in registered_variants())],
)
def test_every_registered_controller_on_every_drive(
    controller: str, every_case: list[Case], every_registered_run: Evaluation
) -> None:
    runs = [r for r in every_registered_run.results if r.controller == controller]
    assert len(runs) == len(every_case)
    collided = [f"{r.case.name}: {r.kpis.collisions}" for r in runs if r.kpis.collisions]
    assert collided == []


# --- any parameters the registry accepts, on the most dangerous drive ---------------------------

# A bound the registry leaves open (the slowdown thresholds, the gap dwell, the lane-change
# detector's) is drawn up to this many times the default's magnitude: far beyond any setting an
# operator would assign, still a number the controller computes with.
OPEN_BOUND_FACTOR = 100.0


def within_bounds(kind: type, metadata: list[Any], default: float) -> st.SearchStrategy[Any]:
    """Numbers of `kind` inside the field's declared bounds (open ones at OPEN_BOUND_FACTOR)."""
    reach = OPEN_BOUND_FACTOR * max(abs(float(default)), 1.0)
    low, high, open_low, open_high = -reach, reach, False, False
    for bound in metadata:
        if isinstance(bound, annotated_types.Gt):
            low, open_low = float(bound.gt), True  # type: ignore[arg-type]
        elif isinstance(bound, annotated_types.Ge):
            low = float(bound.ge)  # type: ignore[arg-type]
        elif isinstance(bound, annotated_types.Lt):
            high, open_high = float(bound.lt), True  # type: ignore[arg-type]
        elif isinstance(bound, annotated_types.Le):
            high = float(bound.le)  # type: ignore[arg-type]
    if kind is int:
        return st.integers(
            math.floor(low) + 1 if open_low else math.ceil(low),
            math.ceil(high) - 1 if open_high else math.floor(high),
        )
    return st.floats(low, high, exclude_min=open_low, exclude_max=open_high, allow_nan=False)


def accepted_params(model: type[BaseModel]) -> st.SearchStrategy[dict[str, Any]]:
    """Parameters the model accepts: every number and switch drawn within its declared bounds,
    nested models likewise; anything else (an RL controller's policy file) keeps its default."""
    fields: dict[str, st.SearchStrategy[Any]] = {}
    for name, info in model.model_fields.items():
        kind = info.annotation
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            fields[name] = accepted_params(kind)
        elif kind is bool:
            fields[name] = st.booleans()
        elif kind in (int, float):
            assert isinstance(kind, type)
            fields[name] = within_bounds(kind, info.metadata, info.default)
    return st.fixed_dictionaries(fields)


def drawable(model: type[BaseModel]) -> bool:
    """True when `accepted_params` draws at least one of the model's fields."""
    return any(
        info.annotation in (int, float, bool)
        or (isinstance(info.annotation, type) and issubclass(info.annotation, BaseModel))
        for info in model.model_fields.values()
    )


# Every registered controller with a parameter to draw, on each actuation it drives.
TUNABLE = [
    (name, actuation)
    for name, schema in CONTROLLER_SCHEMAS.items()
    if drawable(schema.params_model)
    for actuation in sorted(schema.actuations)
]


# The real-INRIX drive whose stale plans hand the car back most often (docs/simulation.md:
# 2 takeovers with 1 AV, 17 with 4 for microaccel_acc; 5 for rl_acc with 4), cut to
# its first DANGER_S seconds (which hold 14 of those 17, from 60 s on), with 4 AVs spread
# through the platoon as `--avs 4` spreads them.
DANGEROUS_DRIVE = "2021-04-07-12-33-03_2T3MWRFVXLW056972_masterArray_0_11294"
DANGER_S = 700.0
DANGER_AVS = 4


@pytest.fixture(scope="module")
def dangerous_case(every_case: list[Case]) -> Case:
    whole = next(
        case
        for case in every_case
        if case.scenario == "shockwave_inrix" and case.drive.name == DANGEROUS_DRIVE
    )
    return Case(whole.scenario, whole.drive.slice(0.0, DANGER_S), inrix=whole.inrix)


@pytest.mark.slow
@pytest.mark.parametrize(("name", "actuation"), TUNABLE)
def test_any_accepted_parameters_on_the_most_dangerous_drive(
    name: str, actuation: str, dangerous_case: Case
) -> None:
    schema = CONTROLLER_SCHEMAS[name]

    @settings(
        max_examples=8,
        deadline=None,
        derandomize=True,
        suppress_health_check=[HealthCheck.too_slow],
    )
    @given(params=accepted_params(schema.params_model))
    def no_collision(params: dict[str, Any]) -> None:
        schema.params_model.model_validate(params)  # the registry accepts them
        variant = ControllerVariant(name, actuation, params)
        assert collisions_on([dangerous_case], variant, avs=DANGER_AVS) == []

    no_collision()
