"""The simulated AVs run the vehicle agent's own controller objects, fed by the real planner."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.av import RADAR_RANGE_M, AgentPolicy, agent_policy
from sim.drives import drive_from_speeds, load_drive
from sim.emulator.acc import SimulatedAccCar
from sim.kpi import platoon_kpis
from sim.plans import ROAD_AFTER_M, ROAD_BEFORE_M, SimulatedPlanner
from sim.platoon import AvObservation, platoon_roles, simulate_platoon
from sim.traffic import InrixFeed, segment_bounds
from vehicle_agent.actuators import AccelLimiter
from vehicle_agent.controllers import (
    CONTROLLERS,
    AccelCommand,
    AccSetPoint,
    Controller,
    Observation,
    TargetProfile,
    build_controller,
)
from vehicle_agent.controllers.microaccel import MicroAccelController

STOP_AND_GO = "trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"


class FixedPlan:
    """A plan of 20 m/s everywhere, and a record of the pings it was sent."""

    def __init__(self) -> None:
        self.pings: list[tuple[float, float, float, bool, bool]] = []

    def profile(self, time_s: float) -> TargetProfile:
        return TargetProfile(np.array([0.0, 1e5]), np.array([20.0, 20.0]))

    def record_ping(
        self, time_s: float, x_m: float, speed_mps: float, *, engaged: bool, lead_present: bool
    ) -> None:
        self.pings.append((time_s, x_m, speed_mps, engaged, lead_present))


def test_the_av_runs_the_agents_controller_and_makes_its_command() -> None:
    plan = FixedPlan()
    policy = agent_policy("microaccel", "accel", plan, {"k": 0.4})
    assert isinstance(policy.controller, MicroAccelController)
    assert policy.controller.params.k == 0.4
    twin = build_controller("microaccel", "accel", {"k": 0.4})
    limiter = AccelLimiter()  # the agent's, between the controller and the car
    limiter.reset(0.0, 0.0)  # taking over a car at constant speed
    for step, (gap, lead) in enumerate([(40.0, 24.0), (39.6, 23.0), (39.0, 22.0)]):
        sensed = AvObservation(step * 0.1, 1000.0 + step, 25.0, gap, lead)
        expected = twin.step(
            Observation(
                time_s=step * 0.1,
                speed_mps=25.0,
                target_speed_mps=20.0,
                position_m=1000.0 + step,
                target=plan.profile(0.0),
                lead_present=True,
                lead_distance_m=gap,
                lead_rel_speed_mps=lead - 25.0,
            )
        )
        request = expected.accel_mps2  # type: ignore[union-attr]
        assert request < -1.0  # closing on a slower leader: a braking the limiter ramps
        assert policy.accel_mps2(sensed) == limiter.limit(step * 0.1, request, speed_mps=25.0)
    # one ping per second; the first is sent before the controller has driven
    assert plan.pings == [(0.0, 1000.0, 25.0, False, True)]


def test_pings_say_whether_the_controller_drove_and_the_radar_saw_a_leader() -> None:
    plan = FixedPlan()
    policy = agent_policy("microaccel", "accel", plan)
    for step in range(31):
        gap = 40.0 if step < 15 else RADAR_RANGE_M + 1.0  # the leader pulls out of range
        sensed = AvObservation(step * 0.1, 1000.0 + 2.5 * step, 25.0, gap, 25.0)
        if step < 25:
            policy.accel_mps2(sensed)
        else:
            policy.driver_drives(sensed)
    # each ping tells what the last step did: not yet driven; driven behind the leader;
    # driven with nothing in range; the driver's since 2.5 s
    assert [(engaged, lead) for *_, engaged, lead in plan.pings] == [
        (False, True),
        (True, True),
        (True, False),
        (False, False),
    ]


class Requesting(Controller):
    """Asks for one acceleration, whatever it sees; counts its resets."""

    name = "requesting"

    def __init__(self, request_mps2: float) -> None:
        super().__init__("accel")
        self.request_mps2 = request_mps2
        self.resets = 0

    def step(self, observation: Observation) -> AccelCommand:
        return AccelCommand(self.request_mps2)

    def reset(self) -> None:
        self.resets += 1


def test_an_accel_cars_commands_pass_the_agents_jerk_limits() -> None:
    """The car sends what the agent's limiter lets through, not the controller's request: from
    the car's 0 m/s^2 a -3 m/s^2 request falls 5 m/s^3 (0.5 a step), and back to +1.5 it rises
    2.5 m/s^3 (0.25 a step)."""
    controller = Requesting(-3.0)
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=True)
    falling = [
        policy.accel_mps2(AvObservation(step / 10, 25.0 * step / 10, 25.0, 200.0, 25.0))
        for step in range(8)
    ]
    assert falling == pytest.approx([0.0, -0.5, -1.0, -1.5, -2.0, -2.5, -3.0, -3.0])
    controller.request_mps2 = 1.5
    rising = [
        policy.accel_mps2(AvObservation(step / 10, 25.0 * step / 10, 25.0, 200.0, 25.0))
        for step in range(8, 12)
    ]
    assert rising == pytest.approx([-2.75, -2.5, -2.25, -2.0])


def test_each_engagement_starts_the_limiter_from_the_cars_acceleration() -> None:
    """After the driver drives, the agent takes over from what the car does then (its speed
    changing 0.2 m/s a step: 2 m/s^2, the range's top 1.5), not from its last request."""
    controller = Requesting(-3.0)
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=True)
    for step in range(10):
        policy.accel_mps2(AvObservation(step / 10, 0.0, 25.0, 200.0, 25.0))
    assert policy.accel_mps2(AvObservation(1.0, 0.0, 25.0, 200.0, 25.0)) == -3.0
    for step in range(10, 20):
        speed = 20.0 + 0.2 * (step - 10)
        policy.driver_drives(AvObservation(step / 10, 0.0, speed, 200.0, 25.0))
    assert controller.resets == 10  # afresh every step the driver drives
    first = policy.accel_mps2(AvObservation(2.0, 0.0, 22.0, 200.0, 25.0))
    assert first == pytest.approx(1.5)  # the car's 2 m/s^2, within the range
    second = policy.accel_mps2(AvObservation(2.1, 0.0, 22.15, 200.0, 25.0))
    assert second == pytest.approx(1.0)  # then falling 5 m/s^3


class RecordingRequest(Requesting):
    """Requesting, keeping the commanded acceleration each observation carries."""

    def __init__(self, request_mps2: float) -> None:
        super().__init__(request_mps2)
        self.commanded: list[float | None] = []

    def step(self, observation: Observation) -> AccelCommand:
        self.commanded.append(observation.commanded_accel_mps2)
        return super().step(observation)


def test_the_controller_sees_what_the_limiter_let_through_and_the_car_at_take_over() -> None:
    """The first observation of an engagement carries the car's acceleration (its speed
    rising 0.1 m/s a step: 1 m/s^2), each next one the limiter's last output as it brakes
    toward -3 m/s^2 at 5 m/s^3."""
    controller = RecordingRequest(-3.0)
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=True)
    policy.driver_drives(AvObservation(0.0, 0.0, 20.0, 200.0, 25.0))
    policy.driver_drives(AvObservation(0.1, 0.0, 20.1, 200.0, 25.0))
    made = [
        policy.accel_mps2(AvObservation(0.2 + step / 10, 0.0, 20.2, 200.0, 25.0))
        for step in range(3)
    ]
    assert controller.commanded == pytest.approx([1.0, 1.0, 0.5])
    assert made == pytest.approx([1.0, 0.5, 0.0])


class Recording(Controller):
    """Records what it is shown and asks for nothing."""

    name = "recording"

    def __init__(self) -> None:
        super().__init__("accel")
        self.seen: list[Observation] = []

    def step(self, observation: Observation) -> AccelCommand:
        self.seen.append(observation)
        return AccelCommand(0.0)


def test_a_leader_beyond_radar_range_is_not_seen() -> None:
    controller = Recording()
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=True)
    policy.accel_mps2(AvObservation(0.0, 0.0, 25.0, RADAR_RANGE_M + 1.0, 25.0))
    policy.accel_mps2(AvObservation(0.1, 2.5, 25.0, RADAR_RANGE_M - 1.0, 24.0))
    far, near = controller.seen
    assert far.lead_present is False
    assert far.lead_distance_m is None
    assert near.lead_present is True
    assert near.lead_distance_m == RADAR_RANGE_M - 1.0
    assert near.lead_rel_speed_mps == pytest.approx(-1.0)


def test_an_accel_car_can_measure_its_leader_as_far_as_the_rav4_does() -> None:
    """The RAV4 reports leaders to 252 m and the agent's controller bounds by them; the
    simulator's accel car measures to `lead_state_range_m` (100 m unless asked), and a policy's
    features still read a leader past 100 m as none (vehicle_agent.controllers.policy)."""
    controller = Recording()
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=True, lead_state_range_m=252.0)
    policy.accel_mps2(AvObservation(0.0, 0.0, 30.0, 150.0, 15.0))
    policy.accel_mps2(AvObservation(0.1, 3.0, 30.0, 260.0, 15.0))
    measured, beyond = controller.seen
    assert (measured.lead_present, measured.lead_distance_m) == (True, 150.0)
    assert measured.lead_rel_speed_mps == pytest.approx(-15.0)
    assert (beyond.lead_present, beyond.lead_distance_m) == (False, None)
    rl_accel = agent_policy(
        "rl_accel", "accel", FixedPlan(), lead_state_range_m=252.0
    )  # the shipped policy: its bound brakes for the queue 150 m ahead, as on the car
    default = agent_policy("rl_accel", "accel", FixedPlan())
    for step in range(10):  # a second closing at 15 m/s from 150 m (the jerk limit acts)
        closing = AvObservation(step * 0.1, step * 3.0, 30.0, 150.0 - step * 1.5, 15.0)
        bounded, unbounded = rl_accel.accel_mps2(closing), default.accel_mps2(closing)
    assert bounded < 0.0 < unbounded


def test_an_acc_car_senses_only_the_minicar_flag() -> None:
    controller = Recording()
    policy = AgentPolicy(controller, FixedPlan(), senses_lead_state=False)
    policy.accel_mps2(AvObservation(0.0, 0.0, 25.0, 30.0, 24.0))
    assert controller.seen[0].lead_present is True
    assert controller.seen[0].lead_distance_m is None
    assert controller.seen[0].lead_rel_speed_mps is None


class PlanLostBetween(FixedPlan):
    """FixedPlan, but none held from `lost_s` until `back_s` (a stale plan, dropped)."""

    def __init__(self, lost_s: float, back_s: float) -> None:
        super().__init__()
        self.lost_s, self.back_s = lost_s, back_s

    def profile(self, time_s: float) -> TargetProfile | None:
        return None if self.lost_s <= time_s < self.back_s else super().profile(time_s)


class Resettable(Recording):
    """Recording, counting the agent's resets."""

    def __init__(self) -> None:
        super().__init__()
        self.resets = 0

    def reset(self) -> None:
        self.resets += 1


def test_without_a_fresh_plan_the_stock_acc_drives_and_the_controller_starts_afresh() -> None:
    controller = Resettable()
    policy = AgentPolicy(controller, PlanLostBetween(1.0, 2.0), senses_lead_state=True)
    accels = [
        policy.accel_mps2(AvObservation(step / 10, 25.0 * step / 10, 25.0, 200.0, 25.0))
        for step in range(30)
    ]
    # the controller decides only while a plan is held (0-1 s and 2-3 s), and is reset once
    assert len(controller.seen) == 20
    assert controller.resets == 1
    assert (policy.plan_hand_backs, policy.steps_without_plan) == (1, 10)
    # meanwhile the car's ACC, resumed at the car's 25 m/s (56 mph) with no leader in range,
    # holds its speed: 0.4 1/s x (56 mph - 25 m/s)
    assert accels[10:20] == pytest.approx([0.4 * (56 * 0.44704 - 25.0)] * 10)
    assert accels[:10] == accels[20:] == [0.0] * 10  # the controller's requests


def test_an_acc_car_without_a_plan_keeps_the_settings_the_agent_left() -> None:
    car = SimulatedAccCar()
    policy = agent_policy("microaccel_acc", "acc", PlanLostBetween(30.0, 1e9), stock_acc=car)
    for step in range(400):
        policy.accel_mps2(AvObservation(step / 10, 25.0 * step / 10, 25.0, 200.0, 25.0))
    left = (car.speed_setting_mph, car.gap_setting)
    assert policy.plan_hand_backs == 1
    for step in range(400, 500):
        policy.accel_mps2(AvObservation(step / 10, 25.0 * step / 10, 25.0, 200.0, 25.0))
    assert (car.speed_setting_mph, car.gap_setting) == left


def test_acc_controllers_need_a_stock_acc_model() -> None:
    with pytest.raises(ValueError, match="stock-ACC model"):
        agent_policy("microaccel_acc", "acc", FixedPlan())


def test_every_registered_controller_can_be_built_for_the_simulator() -> None:
    for name, spec in CONTROLLERS.items():
        if "accel" in spec.schema.actuations:
            assert isinstance(agent_policy(name, "accel", FixedPlan()), AgentPolicy)


def test_planner_runs_every_minute_and_the_plan_ages() -> None:
    steady = drive_from_speeds("steady", np.full(3001, 25.0))
    # an exact feed of the steady traffic (the simulated one has the real feed's errors)
    bounds = segment_bounds(-ROAD_BEFORE_M, float(steady.position_m[-1]) + ROAD_AFTER_M)
    stamps = np.arange(-900.0, 301.0, 60.0)
    speeds = np.full((len(stamps), len(bounds) - 1), 25.0)
    exact = InrixFeed(bounds[:-1], bounds[1:], stamps, speeds, 0.0)
    planner = SimulatedPlanner.for_drive(steady, "kernel_smooth", feed=exact)
    first = planner.profile(0.0)
    assert planner.plans_run == 1
    # steady 25 m/s traffic: the plan says 25 m/s everywhere
    np.testing.assert_allclose(first.target_speed_mps, 25.0, atol=1e-6)
    later = planner.profile(59.9)
    assert planner.plans_run == 1
    # the agent's lookup: downstream by its wave speed (15 km/h upstream) x the plan's age
    assert later.shift_m == pytest.approx(59.9 * 15.0 / 3.6)
    planner.profile(60.0)
    assert planner.plans_run == 2


def _plan_after_slow_pings(rule: str, *, engaged: bool, lead_present: bool) -> np.ndarray:
    """The second plan over steady 25 m/s traffic (exact INRIX) after a minute of pings at
    10 m/s around x = 1,000 m."""
    steady = drive_from_speeds("steady", np.full(3001, 25.0))
    bounds = segment_bounds(-ROAD_BEFORE_M, float(steady.position_m[-1]) + ROAD_AFTER_M)
    stamps = np.arange(-900.0, 301.0, 60.0)
    exact = InrixFeed(
        bounds[:-1], bounds[1:], stamps, np.full((len(stamps), len(bounds) - 1), 25.0), 0.0
    )
    planner = SimulatedPlanner.for_drive(
        steady, "kernel_smooth", {"engaged_pings": rule}, feed=exact
    )
    planner.profile(0.0)
    for second in range(1, 61):
        planner.record_ping(float(second), 1000.0, 10.0, engaged=engaged, lead_present=lead_present)
    return planner.held_profile(60.0).target_speed_mps


def test_an_engaged_car_alone_on_its_radar_feeds_the_plan_only_under_all() -> None:
    echo = {"engaged": True, "lead_present": False}
    # the paper's design: every ping is an observation, the plan's own echo included
    assert _plan_after_slow_pings("all", **echo).min() < 24.0
    # "behind_leader": nothing but the plan set that car's speed, so the plan ignores it
    np.testing.assert_allclose(_plan_after_slow_pings("behind_leader", **echo), 25.0, atol=1e-6)
    # behind a leader, or on its stock ACC, the car's speed is the traffic's: it counts
    for counted in (
        {"engaged": True, "lead_present": True},
        {"engaged": False, "lead_present": False},
    ):
        assert _plan_after_slow_pings("behind_leader", **counted).min() < 24.0


def test_one_av_smooths_a_real_stop_and_go_slice(shared_dir: Path) -> None:
    drive = load_drive(shared_dir / "data" / STOP_AND_GO).slice(300.0, 300.0)
    humans = simulate_platoon(drive, platoon_roles(humans=24, avs=0))
    planner = SimulatedPlanner.for_drive(drive, "kernel_smooth")
    policy = agent_policy("microaccel", "accel", planner)
    mixed = simulate_platoon(drive, platoon_roles(humans=24, avs=1), [policy])
    assert mixed.collisions == 0
    assert planner.plans_run == 5
    # the AV damps the waves: better fuel economy and smoother driving behind it
    assert platoon_kpis(mixed).fuel_economy_mpg > platoon_kpis(humans).fuel_economy_mpg
    assert platoon_kpis(mixed).accel_rms_mps2 < platoon_kpis(humans).accel_rms_mps2
    assert mixed.speed_mps[:, -1].std() < humans.speed_mps[:, -1].std()


def test_an_acc_av_drives_through_the_emulators_stock_acc() -> None:
    # The controller's set points go through the car emulator's ACC (buttons and all); a twin
    # controller + ACC fed the same observations makes the same accelerations.
    plan = FixedPlan()
    policy = agent_policy("microaccel_acc", "acc", plan, stock_acc=SimulatedAccCar())
    twin_controller = build_controller("microaccel_acc", "acc")
    twin_car = SimulatedAccCar()
    speeds = []
    for step in range(40):
        t = step * 0.1
        sensed = AvObservation(t, 25.0 * t, 25.0, 60.0, 24.0)
        action = twin_controller.step(
            Observation(
                time_s=t,
                speed_mps=25.0,
                target_speed_mps=20.0,
                position_m=25.0 * t,
                target=plan.profile(t),
                lead_present=True,
                acc_speed_setting_mph=twin_car.speed_setting_mph,
                acc_gap_setting=twin_car.gap_setting,
            )
        )
        assert isinstance(action, AccSetPoint)
        expected = twin_car.accel_mps2(action, t, 25.0, 60.0, 24.0)
        assert policy.accel_mps2(sensed) == expected
        speeds.append(twin_car.speed_setting_mph)
    # the plan says 20 m/s (44.7 mph): the buttons bring the set speed down from 56 mph
    assert speeds[0] == 56.0
    assert speeds[-1] is not None
    assert speeds[-1] < 56.0


def test_a_platoon_behind_an_acc_av(shared_dir: Path) -> None:
    drive = load_drive(shared_dir / "data" / STOP_AND_GO).slice(300.0, 300.0)
    planner = SimulatedPlanner.for_drive(drive, "kernel_smooth")
    policy = agent_policy("microaccel_acc", "acc", planner, stock_acc=SimulatedAccCar())
    run = simulate_platoon(drive, platoon_roles(humans=24, avs=1), [policy])
    assert run.collisions == 0
    assert run.gap_violations == 0
