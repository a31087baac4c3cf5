"""The controller registry, the simple and MicroAccel-ACC controllers and the paper's ACC clip."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.vehicles.schemas import CONTROLLER_ACTUATIONS
from contract.controllers import CONTROLLER_SCHEMAS, ControllerConfigError, controller_actuations
from contract.units import MPS_PER_MPH, mps_to_mph
from vehicle_agent.controllers import (
    CONTROLLERS,
    AccelCommand,
    AccSetPoint,
    NonFiniteAction,
    Observation,
    TargetProfile,
    build_controller,
    clip_speed_setting,
)
from vehicle_agent.controllers.microaccel_acc import ahead_accel
from vehicle_agent.controllers.registry import BUILDERS


def test_clip_uses_the_mean_of_the_last_second_without_zero_and_missing_speeds() -> None:
    # Valid samples: 60, 60, 61, 62, 60, 59, 61, 61 -> mean 60.5; bounds [45.5, 65.5].
    recent = [60.0, 60.0, 0.0, 61.0, None, 62.0, 60.0, 59.0, 61.0, 61.0]
    assert clip_speed_setting(70.0, recent) == 66  # 65.5 rounds half up
    assert clip_speed_setting(40.0, recent) == 46  # 45.5
    assert clip_speed_setting(58.2, recent) == 58
    # half up, not Python's half to even (which agrees on 65.5 and 45.5 above)
    assert clip_speed_setting(44.5, []) == 45
    assert clip_speed_setting(46.5, [50.0] * 10) == 47


def test_clip_keeps_the_setting_within_20_and_73_mph() -> None:
    # Mean 10 mph: v_clip = min(max(30, -5), 15) = 15 -> raised to 20.
    assert clip_speed_setting(30.0, [10.0] * 10) == 20
    # Mean 72 mph: 76 is inside [57, 77] but above 73.
    assert clip_speed_setting(76.0, [72.0] * 10) == 73
    # No valid speed at all: only the [20, 73] bounds apply.
    assert clip_speed_setting(35.4, [0.0, None]) == 35


def test_the_clip_refuses_a_request_that_is_not_a_number() -> None:
    # Before, NaN became the 20 mph floor: a setting no controller chose.
    for request in (math.nan, math.inf):
        with pytest.raises(NonFiniteAction, match="speed setting request"):
            clip_speed_setting(request, [60.0] * 10)


def test_registry_is_what_the_server_validates_against() -> None:
    assert set(CONTROLLERS) == {"simple", "microaccel", "microaccel_acc", "rl_acc", "rl_accel"}
    assert controller_actuations() == {
        "simple": frozenset({"acc", "accel"}),
        "microaccel": frozenset({"accel"}),
        "microaccel_acc": frozenset({"acc"}),
        "rl_acc": frozenset({"acc"}),
        "rl_accel": frozenset({"accel"}),
    }
    assert CONTROLLER_ACTUATIONS == controller_actuations()
    # every controller of the contract has an implementation, and only those
    assert set(BUILDERS) == set(CONTROLLER_SCHEMAS)


def test_bad_configuration_is_named() -> None:
    with pytest.raises(ControllerConfigError, match="'pid' is not one of microaccel, "):
        build_controller("pid", "acc")
    with pytest.raises(ControllerConfigError, match="cannot drive actuation 'acc'"):
        build_controller("microaccel", "acc")
    with pytest.raises(ControllerConfigError, match=r"params\.k: Input should be greater than 0"):
        build_controller("microaccel", "accel", {"k": -1})
    with pytest.raises(ControllerConfigError, match=r"params\.gain: Extra inputs"):
        build_controller("simple", "acc", {"gain": 1})
    with pytest.raises(ControllerConfigError, match=r"params\.lane_change\.c"):
        build_controller("microaccel", "accel", {"lane_change": {"c": 2}})


def test_simple_on_an_acc_car_asks_for_the_target_within_the_clip() -> None:
    controller = build_controller("simple", "acc", {})
    # Target 25 m/s = 55.92 mph, but the car has been doing 20 m/s = 44.74 mph:
    # v_upper = 44.74 + 5 = 49.74 -> 50 mph.
    action = controller.step(Observation(time_s=0.0, speed_mps=20.0, target_speed_mps=25.0))
    assert action == AccSetPoint(50, 3)
    assert action.requested_speed_mph == pytest.approx(55.923, abs=1e-3)  # type: ignore[union-attr]


def test_simple_on_an_accel_car_is_bounded_and_respects_the_leader() -> None:
    controller = build_controller("simple", "accel", {})
    free = controller.step(Observation(time_s=0.0, speed_mps=10.0, target_speed_mps=30.0))
    assert free == AccelCommand(1.0)
    # Target above, but 12 m behind a stopped car: the safety term brakes.
    blocked = controller.step(
        Observation(
            0.1, 10.0, 30.0, lead_present=True, lead_distance_m=12.0, lead_rel_speed_mps=-10.0
        )
    )
    assert isinstance(blocked, AccelCommand)
    assert blocked.accel_mps2 == -3.0


def test_microaccel_acc_anticipates_a_slowdown_ahead() -> None:
    profile = TargetProfile(
        np.array([0.0, 1000.0, 1500.0, 3000.0]), np.array([30.0, 30.0, 15.0, 15.0])
    )
    controller = build_controller("microaccel_acc", "acc", {})
    observation = Observation(
        time_s=0.0,
        speed_mps=30.0,
        target_speed_mps=30.0,
        position_m=1000.0,
        target=profile,
        acc_gap_setting=2,
    )
    # Look-ahead max(30 * 20, 200) = 600 m -> target 15 m/s at x = 1600:
    # a_ahead = (15^2 - 30^2) / (2 * 600) = -0.5625; a_target = 0 -> a = -0.5625,
    # setting = 30 - 0.5625 * 2 = 28.875 m/s = 64.59 mph; gap bars widen to 3.
    assert ahead_accel(30.0, 15.0, 600.0) == pytest.approx(-0.5625)
    action = controller.step(observation)
    assert action == AccSetPoint(65, 3)
    assert action.requested_speed_mph == pytest.approx(64.5915, abs=1e-4)  # type: ignore[union-attr]


def test_microaccel_acc_anticipates_no_harder_than_its_planned_braking() -> None:
    """A short look-ahead (0.5 s, 10 m floor: in the params' ranges) onto a plan dropping from
    30 to 5 m/s 10 m ahead asks a_ahead = (5^2 - 30^2) / (2 * 15) = -29.2 m/s^2; the request is
    bounded by a_min (-3): 30 - 3 * 2 = 24 m/s = 53.69 mph, not a setting far below the car
    (a mutant without the bound passed every test)."""
    profile = TargetProfile(
        np.array([0.0, 1010.0, 1010.01, 2000.0]), np.array([30.0, 30.0, 5.0, 5.0])
    )
    controller = build_controller(
        "microaccel_acc", "acc", {"lookahead_s": 0.5, "min_lookahead_m": 10.0}
    )
    action = controller.step(
        Observation(0.0, 30.0, 30.0, position_m=1000.0, target=profile, acc_gap_setting=2)
    )
    assert ahead_accel(30.0, 5.0, 15.0) == pytest.approx(-875.0 / 30.0)
    assert action.requested_speed_mph == pytest.approx(mps_to_mph(24.0), abs=1e-6)  # type: ignore[union-attr]


def test_microaccel_acc_holds_the_gap_for_the_dwell_time() -> None:
    slow_ahead = TargetProfile(np.array([0.0, 500.0, 600.0]), np.array([30.0, 30.0, 10.0]))
    free = TargetProfile(np.array([0.0, 600.0]), np.array([30.0, 30.0]))
    controller = build_controller("microaccel_acc", "acc", {"gap_dwell_s": 10.0})

    def gap_at(time_s: float, profile: TargetProfile) -> int:
        action = controller.step(
            Observation(time_s, 30.0, 30.0, position_m=100.0, target=profile, acc_gap_setting=2)
        )
        assert isinstance(action, AccSetPoint)
        return action.gap_setting

    assert gap_at(0.0, slow_ahead) == 3
    assert gap_at(1.0, free) == 3  # changed 1 s ago: held
    assert gap_at(10.0, free) == 2


def test_target_profile_shifts_its_lookup_downstream() -> None:
    profile = TargetProfile(np.array([0.0, 1000.0]), np.array([10.0, 30.0]), shift_m=250.0)
    assert profile.at(250.0) == pytest.approx(20.0)


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
speeds = st.floats(min_value=0.0, max_value=60.0)


@settings(max_examples=300, deadline=None)
@given(
    name_actuation=st.sampled_from(
        [("simple", "acc"), ("simple", "accel"), ("microaccel", "accel"), ("microaccel_acc", "acc")]
    ),
    steps=st.lists(
        st.tuples(
            speeds,
            speeds,
            st.booleans(),
            st.one_of(st.none(), finite),
            st.one_of(st.none(), finite),
            st.one_of(st.none(), finite),
        ),
        min_size=1,
        max_size=20,
    ),
)
def test_any_finite_observation_gives_a_bounded_action(
    name_actuation: tuple[str, str],
    steps: list[tuple[float, float, bool, float | None, float | None, float | None]],
) -> None:
    name, actuation = name_actuation
    controller = build_controller(name, actuation, {})
    profile = TargetProfile(np.array([0.0, 5000.0]), np.array([30.0, 10.0]))
    for index, (speed, target, lead, gap, rel, position) in enumerate(steps):
        action = controller.step(
            Observation(
                time_s=index * 0.1,
                speed_mps=speed,
                target_speed_mps=target,
                position_m=position,
                target=profile,
                lead_present=lead,
                lead_distance_m=None if gap is None else abs(gap),
                lead_rel_speed_mps=rel,
            )
        )
        if isinstance(action, AccelCommand):
            assert math.isfinite(action.accel_mps2)
            assert -3.0 <= action.accel_mps2 <= 1.5
        else:
            assert 20 <= action.speed_setting_mph <= 73
            assert action.gap_setting in (1, 2, 3)


@pytest.mark.parametrize(
    ("name", "actuation"),
    [
        ("simple", "accel"),
        ("microaccel", "accel"),
        ("microaccel_acc", "acc"),
        ("rl_accel", "accel"),
    ],
)
def test_a_slower_car_cutting_in_far_ahead_is_no_leader_braking_hard(
    name: str, actuation: str
) -> None:
    """A car cutting in at 60 m, 5 m/s slower (12 s to collision), replaces a leader at 100 m
    holding the AV's speed. Its lower speed is not the old leader braking: the leader's
    acceleration estimate starts afresh, and no controller brakes near its -3 m/s^2 limit for it
    (with the old leader's history, simple and rl_accel asked for -3 for 0.6 s and more)."""
    controller = build_controller(name, actuation)
    time_s = 0.0
    for _ in range(50):
        controller.step(Observation(time_s, 25.0, 25.0, None, None, True, 100.0, 0.0))
        time_s += 0.1
    estimates = []
    for step in range(10):
        observation = Observation(time_s, 25.0, 25.0, None, None, True, 60.0 - 0.5 * step, -5.0)
        action = controller.step(observation)
        estimates.append(getattr(controller, "inner", controller).lead_accel.accel_mps2)
        if isinstance(action, AccelCommand):
            assert action.accel_mps2 > -2.0, (step, action)
        time_s += 0.1
    assert estimates == [0.0] * 10  # the new leader holds its speed


def test_the_clip_window_is_the_last_second_even_across_a_hand_back() -> None:
    """The clip's controller steps only while engaged: speeds from before a hand-back are no
    part of "the last second" at the next take-over (paper: the last 1 s of ego speeds)."""
    controller = build_controller("simple", "acc")
    for step in range(10):
        controller.step(Observation(step * 0.1, 30.0 * MPS_PER_MPH, 70.0 * MPS_PER_MPH))
    controller.reset()  # handed back, taken over again ten minutes later at 70 mph
    later = 600.0
    action = controller.step(Observation(later, 70.0 * MPS_PER_MPH, 70.0 * MPS_PER_MPH))
    assert isinstance(action, AccSetPoint)
    assert action.speed_setting_mph == 70  # not clipped to 30 + 5 mph


def test_a_controller_with_a_schema_and_no_builder_stops_the_import_naming_it() -> None:
    """The contract's schemas and the agent's builders are two registries: a schema alone was
    accepted by the server for cars that could not build it, a builder alone left out."""
    code = (
        "import contract.controllers as c\n"
        "c.CONTROLLER_SCHEMAS['hold'] = c.CONTROLLER_SCHEMAS['simple']\n"
        "import vehicle_agent.controllers\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 1
    assert "RegistryMismatch: controllers with a schema but no builder: ['hold']" in result.stderr
