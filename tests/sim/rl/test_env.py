"""The RL training environment: the paper's MDP over many platoons at once."""

from __future__ import annotations

import numpy as np
import pytest

from contract.idm import I24_IDM, idm_accel
from sim.drives import Drive, drive_from_speeds
from sim.energy import RAV4_2019
from sim.plans import MIN_TARGET_SPEED_MPS
from sim.platoon import VEHICLE_LENGTH_M, CutIns
from sim.recorded import RecordedDrive
from sim.rl.env import MAX_MERGED_CARS, EnvConfig, PlatoonVecEnv, RewardWeights
from sim.traffic import InrixFeed, segment_bounds

STEADY = drive_from_speeds("2021-01-01-steady", np.full(6001, 20.0))
ONLY_GAP = RewardWeights(accel=0.0, speed=0.0, fuel=0.0, gap=1.0, collision=1.0)


def steady_env(
    actuation: str,
    reward: RewardWeights,
    envs: int = 2,
    episode_s: float = 60.0,
    cut_ins: CutIns | None = None,
) -> PlatoonVecEnv:
    """A platoon behind a steady 20 m/s leader; without cut-ins unless asked, so a test of
    one term does not meet a car merging into a gap it set."""
    config = EnvConfig(
        "acc" if actuation == "acc" else "accel",
        humans=3,
        episode_s=episode_s,
        reward=reward,
        cut_ins=cut_ins,
    )
    env = PlatoonVecEnv([STEADY], envs, config)
    env.reset(seed=1)
    return env


def place_av(env: PlatoonVecEnv, gap_m: float) -> None:
    env.position[:, 1] = env.position[:, 0] - VEHICLE_LENGTH_M - gap_m


def test_observations_and_actions_are_batched_rows() -> None:
    env = PlatoonVecEnv([STEADY], 4, EnvConfig("acc", humans=3, episode_s=60.0))
    observation, _ = env.reset(seed=3)
    assert observation.shape == (4, 6)
    assert env.action_space.shape == (4, 2)
    # v = 20 m/s (features / 30); v_s here and 500 m ahead as the planner's plan says
    np.testing.assert_allclose(observation[:, 0], 20.0 / 30.0)
    for env_index, planner in enumerate(env.planners):
        time_s = float(env.start_step[env_index]) * 0.1
        profile = planner.profile(time_s)
        x = float(env.position[env_index, 1])
        assert observation[env_index, 1] == pytest.approx(profile.at(x) / 30.0)
        assert observation[env_index, 2] == pytest.approx(profile.at(x + 500.0) / 30.0)
    np.testing.assert_array_equal(observation[:, 3], 1.0)
    observation, reward, terminated, truncated, _ = env.step(np.zeros((4, 2)))
    assert observation.shape == (4, 6)
    assert reward.shape == (4,)
    assert not terminated.any()
    assert not truncated.any()


def test_reward_without_penalties_is_one() -> None:
    env = steady_env("accel", RewardWeights(0.0, 0.0, 0.0, 0.0, 0.0))
    _, reward, *_ = env.step(np.zeros((2, 1)))
    np.testing.assert_array_equal(reward, 1.0)


def test_fuel_term_is_the_mean_fuel_rate_of_the_av_and_the_humans_behind() -> None:
    env = steady_env("accel", RewardWeights(0.0, 0.0, 1.0, 0.0, 0.0))
    # the AV 60 m behind the leader (free to hold its speed), the humans at their spacing
    env.position[:, 1:] -= (
        60.0 - (env.position[:, 0] - env.position[:, 1] - VEHICLE_LENGTH_M)[:, None]
    )
    before = env.speed[:, 1:].copy()
    _, reward, *_ = env.step(np.zeros((2, 1)))
    accel = (env.speed[:, 1:] - before) / 0.1
    expected = 1.0 - RAV4_2019.fuel_rate_gps(before, accel).mean(axis=1)
    np.testing.assert_allclose(reward, expected)
    # everyone steady at 20 m/s: f = c0 + c1 v + c3 v^3 = 0.1463 + 0.2436 + 0.2195 = 0.609 g/s
    assert reward[0] == pytest.approx(1.0 - 0.609, abs=0.001)


@pytest.mark.parametrize(
    ("gap_m", "reward"),
    [
        (50.0, 1.0),  # 2.5 s at 20 m/s: inside
        (130.0, 0.0),  # beyond h_max = 120 m
        (15.0, 0.0),  # 0.75 s: under the 1 s minimum time gap
    ],
)
def test_gap_term_is_the_papers_intervention_penalty(gap_m: float, reward: float) -> None:
    env = steady_env("accel", ONLY_GAP)
    place_av(env, gap_m)
    _, rewards, *_ = env.step(np.zeros((2, 1)))
    np.testing.assert_allclose(rewards, reward)


def test_speed_term_is_the_square_of_the_distance_to_the_plan() -> None:
    env = steady_env("accel", RewardWeights(0.0, 0.01, 0.0, 0.0, 0.0))
    env.speed[:, 1] = 25.0
    plan = env.target_here.copy()
    # 0.01 per (m/s)^2 off the plan's target at the AV (e.g. 5 m/s off costs 0.25)
    _, reward, *_ = env.step(np.zeros((2, 1)))
    np.testing.assert_allclose(reward, 1.0 - 0.01 * (25.0 - plan) ** 2)


def test_a_collision_ends_the_episode_with_the_steps_left_as_penalty() -> None:
    env = steady_env("accel", ONLY_GAP)
    place_av(env, 50.0)
    env.position[0, 1] = env.position[0, 0] - VEHICLE_LENGTH_M - 0.5
    env.speed[0, 1] = 30.0  # closing at 10 m/s: touches within the step
    _, reward, terminated, truncated, infos = env.step(np.zeros((2, 1)))
    assert terminated.tolist() == [True, False]
    assert not truncated.any()
    # outside the bounds (0) and 599 steps left of 600
    assert reward[0] == pytest.approx(0.0 - 599.0)
    assert infos["_final_obs"].tolist() == [True, False]
    assert env.elapsed[0] == 0  # restarted within the same step


def test_episodes_are_truncated_at_their_length() -> None:
    env = steady_env("accel", ONLY_GAP, episode_s=1.0)
    for _ in range(9):
        _, _, terminated, truncated, _ = env.step(np.zeros((2, 1)))
        assert not truncated.any()
    _, _, terminated, truncated, infos = env.step(np.zeros((2, 1)))
    assert truncated.all()
    assert not terminated.any()
    assert infos["final_obs"].shape == (2, 6)


def test_acc_actions_go_through_the_clip_and_the_button_sequencer_gap_first() -> None:
    env = steady_env("acc", ONLY_GAP, envs=1)
    car = env.cars[0]
    assert (car.acc.set_speed_mph, car.acc.gap_setting) == (45, 3)  # 20 m/s = 44.7 mph
    # ask for 1 bar and +5 mph (the clip's ceiling over the last second's mean)
    settings = []
    for _ in range(60):
        env.step(np.array([[1.0, -1.0]]))
        settings.append((car.acc.set_speed_mph, car.acc.gap_setting))
    # one press per 0.5 s: the gap moves 3 -> 2 -> 1 before the speed setting moves at all
    first_speed_change = next(i for i, (speed, _) in enumerate(settings) if speed != 45)
    first_gap_one = next(i for i, (_, gap) in enumerate(settings) if gap == 1)
    assert first_gap_one < first_speed_change
    assert settings[0] == (45, 3)
    # never above the clip's ceiling: the last second's mean speed + 5 mph
    for step, (speed, _) in enumerate(settings):
        assert speed <= 45 + 5 * (1 + step // 10)


def test_the_same_seed_starts_the_same_windows() -> None:
    other = drive_from_speeds("2021-01-02-other", np.linspace(10.0, 30.0, 9001))
    drives: list[Drive] = [STEADY, other]
    first = PlatoonVecEnv(drives, 8, EnvConfig("accel", humans=2, episode_s=60.0))
    second = PlatoonVecEnv(drives, 8, EnvConfig("accel", humans=2, episode_s=60.0))
    first.reset(seed=5)
    second.reset(seed=5)
    np.testing.assert_array_equal(first.start_step, second.start_step)
    np.testing.assert_array_equal(first.road_index, second.road_index)


def test_an_acc_av_that_lost_its_leader_closes_up_whatever_the_policy_asks() -> None:
    """The closing rule in training: beyond the radar's range the request is the clip's
    ceiling, so even a policy asking for the least speed sees its setting rise."""
    lost = steady_env("acc", ONLY_GAP, envs=1)
    place_av(lost, 150.0)
    seen = steady_env("acc", ONLY_GAP, envs=1)
    place_av(seen, 50.0)
    for _ in range(20):
        lost.step(np.array([[-1.0, 0.0]]))
        seen.step(np.array([[-1.0, 0.0]]))
    # 20 m/s = 45 mph at the start; the clip lets the lost car's setting rise 5 mph over its
    # last second's mean, while the car that sees its leader is asked for plan - 20 mph
    assert lost.cars[0].acc.set_speed_mph is not None
    assert seen.cars[0].acc.set_speed_mph is not None
    assert lost.cars[0].acc.set_speed_mph > 45
    assert seen.cars[0].acc.set_speed_mph < 45


def test_a_time_margin_action_holds_the_av_further_back() -> None:
    """Two outputs for the margin action; at 20 m/s 40 m behind a steady leader, a_safe alone
    lets a +1.5 m/s^2 request close in, the 1.5 s margin (30 m) brakes."""
    config = EnvConfig("accel", "request_time_margin", humans=3, episode_s=60.0, reward=ONLY_GAP)
    env = PlatoonVecEnv([STEADY], 2, config)
    env.reset(seed=1)
    assert env.action_space.shape == (2, 2)
    place_av(env, 40.0)
    for _ in range(2):  # the first step's command is the car's own 0 m/s^2 (the limiter's start)
        env.step(np.array([[1.0, -1.0], [1.0, 1.0]]))
    assert env.speed[0, 1] > 20.0
    assert env.speed[1, 1] < 20.0


def test_accel_requests_reach_the_car_through_the_agents_limiter() -> None:
    """The policy asks for -3 m/s^2 from a steady platoon: the car brakes as the agent's
    `AccelLimiter` lets it, from its 0 m/s^2 down 5 m/s^3 (0.5 m/s^2 a 0.1 s step)."""
    env = steady_env("accel", ONLY_GAP)
    speeds = []
    for _ in range(4):
        env.step(np.full((2, 1), -1.0))
        speeds.append(env.speed[:, 1].copy())
    made = np.diff(np.vstack([np.full(2, 20.0), *speeds]), axis=0) / 0.1
    np.testing.assert_allclose(made, [[0.0] * 2, [-0.5] * 2, [-1.0] * 2, [-1.5] * 2], atol=1e-9)


def test_the_commanded_accel_observation_reads_what_the_limiter_let_through() -> None:
    """A seventh input, the limiter's last output / 3 m/s^2: 0 as the episode starts (the car
    taken over in equilibrium), then the -3 m/s^2 request's ramp, 0, -0.5, -1.0 m/s^2."""
    config = EnvConfig("accel", accel_observation="commanded_accel", humans=3, episode_s=60.0)
    env = PlatoonVecEnv([STEADY], 2, config)
    observation, _ = env.reset(seed=1)
    assert env.observation_space.shape == (2, 7)
    np.testing.assert_array_equal(observation[:, 6], 0.0)
    seen = []
    for _ in range(3):
        observation, *_ = env.step(np.full((2, 1), -1.0))
        seen.append(observation[:, 6].copy())
    np.testing.assert_allclose(seen, [[0.0] * 2, [-0.5 / 3] * 2, [-1.0 / 3] * 2], atol=1e-12)
    radar = PlatoonVecEnv([STEADY], 2, EnvConfig("accel", humans=3, episode_s=60.0))
    first, _ = radar.reset(seed=1)
    assert first.shape == (2, 6)


def test_a_recorded_drive_plans_from_its_own_inrix_minutes() -> None:
    """Beside a drive on simulated INRIX, a recorded one whose feed read 8 m/s everywhere, from
    ten minutes before the drive on: its platoons' plans hold the planner's 20 mph floor, while
    those on the simulated feed of a steady 20 m/s leader stay well above it."""
    recorded_drive = drive_from_speeds("2021-01-01-recorded", np.full(6001, 20.0))
    bounds = segment_bounds(-2000.0, 14000.0)
    stamps = np.arange(-600.0, 601.0, 60.0)
    feed = InrixFeed(
        bounds[:-1], bounds[1:], stamps, np.full((len(stamps), len(bounds) - 1), 8.0), 0.0
    )
    config = EnvConfig("accel", humans=3, episode_s=60.0)
    env = PlatoonVecEnv([STEADY], 8, config, [RecordedDrive(recorded_drive, feed)])
    env.reset(seed=1)
    assert env.roads[1].feed is feed
    on_recorded = env.road_index == 1
    assert 0 < on_recorded.sum() < 8
    np.testing.assert_allclose(env.target_here[on_recorded], MIN_TARGET_SPEED_MPS)
    assert np.all(env.target_here[~on_recorded] > 12.0)


def test_configuration_errors_say_what_is_wrong() -> None:
    with pytest.raises(ValueError, match="at least one human"):
        EnvConfig("acc", humans=0)
    with pytest.raises(ValueError, match="for accel policies, not acc"):
        EnvConfig("acc", "request_time_margin")
    with pytest.raises(ValueError, match="observation 'commanded_accel' is for accel policies"):
        EnvConfig("acc", accel_observation="commanded_accel")
    with pytest.raises(ValueError, match="no drive is longer than an episode"):
        PlatoonVecEnv([STEADY], 2, EnvConfig("acc", episode_s=1000.0))
    with pytest.raises(ValueError, match="non-finite action"):
        steady_env("accel", ONLY_GAP).step(np.full((2, 1), np.nan))


def test_a_car_merges_into_the_middle_of_a_wide_gap_and_leads_the_av() -> None:
    """Hand-worked: 200 m behind a steady 20 m/s leader the AV leaves (200 - 19) / 20 = 9.05 s,
    6.05 s beyond the 3 s a merging driver accepts: a hazard of 0.605 merges/s. A car merges
    at the gap's middle (97.5 m to either side, 5 m cars) at 20 m/s and becomes the AV's
    leader: its gap is in the envelope, where 200 m was beyond h_max."""
    env = steady_env("accel", ONLY_GAP, cut_ins=CutIns())
    place_av(env, 200.0)
    env.merge_threshold[:] = [0.0, np.inf]  # the first env's draw is reached at once
    leader_x = env.position[:, 0].copy()
    features, reward, _, _, infos = env.step(np.zeros((2, 1)))
    assert infos["cut_ins"].tolist() == [True, False]
    assert env.merged.tolist() == [1, 0]
    np.testing.assert_allclose(env.merge_clock, [0.0, 0.0605])
    # merged at leader - 102.5 m, then one step from 20 m/s as an I-24 IDM driver 97.5 m
    # behind a car as fast as it
    pull = float(idm_accel(I24_IDM, np.array(97.5), np.array(20.0), np.array(20.0)))
    assert env.merged_position[0, 0] == pytest.approx(leader_x[0] - 102.5 + 2.0 + 0.005 * pull)
    assert env.merged_speed[0, 0] == pytest.approx(20.0 + 0.1 * pull)
    # the AV's radar sees the merged car 97.5 m ahead (features: l, gap / 100 m); the other
    # AV's leader is beyond its 100 m range
    np.testing.assert_allclose(features[:, 3], [1.0, 0.0])
    assert features[0, 4] == pytest.approx((97.5 + 0.005 * pull) / 100.0)
    np.testing.assert_allclose(reward, [1.0, 0.0])


def test_no_car_merges_into_a_gap_the_av_keeps_short() -> None:
    """50 m at 20 m/s is 1.55 s beyond the merging car's room: no hazard, the clock stays."""
    env = steady_env("accel", ONLY_GAP, cut_ins=CutIns())
    place_av(env, 50.0)
    for _ in range(100):
        _, _, _, _, infos = env.step(np.zeros((2, 1)))
        assert not infos["cut_ins"].any()
    np.testing.assert_array_equal(env.merge_clock, 0.0)
    assert env.merged.tolist() == [0, 0]


def test_the_av_follows_the_last_car_that_merged_and_a_new_episode_has_none() -> None:
    env = steady_env("accel", ONLY_GAP, envs=1, episode_s=1.0, cut_ins=CutIns())
    place_av(env, 300.0)
    for expected in (1, 2):
        env.merge_threshold[:] = 0.0
        env.step(np.zeros((1, 1)))
        assert env.merged[0] == expected
    # the second merged into the middle of the AV's gap to the first: ~72 m from the AV
    lead_position, _ = env._av_leader()
    assert lead_position[0] == env.merged_position[0, 1]
    gap = lead_position[0] - env.position[0, 1] - VEHICLE_LENGTH_M
    assert gap == pytest.approx((300.0 - 5.0) / 4 - 2.5, abs=0.5)
    # the episode's end (10 steps) clears them
    for _ in range(8):
        env.step(np.zeros((1, 1)))
    assert env.elapsed[0] == 0
    assert env.merged[0] == 0
    assert np.isnan(env.merged_position[0]).all()


def test_cut_ins_leave_the_windows_drawn_as_without_them() -> None:
    drives: list[Drive] = [STEADY, drive_from_speeds("2021-01-02-b", np.linspace(10, 30, 9001))]
    plain = PlatoonVecEnv(drives, 8, EnvConfig("accel", humans=2, episode_s=60.0, cut_ins=None))
    merging = PlatoonVecEnv(drives, 8, EnvConfig("accel", humans=2, episode_s=60.0))
    plain.reset(seed=5)
    merging.reset(seed=5)
    np.testing.assert_array_equal(plain.start_step, merging.start_step)
    np.testing.assert_array_equal(plain.road_index, merging.road_index)


def test_no_car_merges_while_the_room_ahead_of_the_av_is_full() -> None:
    """With MAX_MERGED_CARS ahead of it, the AV 300 m behind the last one invites a merge
    (hazard 0.1 x ((300 - 19) / 20 - 3) = 1.105/s) and its draw is reached at once, yet no car
    merges and the clock waits, so the room's bound is never written past."""
    env = steady_env("accel", ONLY_GAP, envs=1, cut_ins=CutIns())
    leader = float(env.position[0, 0])
    spacing = 40.0
    env.merged_position[0] = leader - spacing * np.arange(1, MAX_MERGED_CARS + 1)
    env.merged_speed[0] = 20.0
    env.merged[0] = MAX_MERGED_CARS
    env.position[0, 1] = env.merged_position[0, -1] - VEHICLE_LENGTH_M - 300.0
    env.merge_threshold[:] = 0.0
    _, _, _, _, infos = env.step(np.zeros((1, 1)))
    assert not infos["cut_ins"].any()
    assert env.merged[0] == MAX_MERGED_CARS
    assert env.merge_clock[0] == 0.0
    # with one place free the same gap takes a car at once
    env.merged[0] = MAX_MERGED_CARS - 1
    env.merged_position[0, -1] = np.nan
    env.merged_speed[0, -1] = np.nan
    _, _, _, _, infos = env.step(np.zeros((1, 1)))
    assert infos["cut_ins"].tolist() == [True]
    assert env.merged[0] == MAX_MERGED_CARS


def spread_platoon(env: PlatoonVecEnv) -> None:
    """The AV 60 m behind the leader at 20 m/s, the humans 60 m apart behind it at 10 m/s:
    every follower free of its leader, the humans speeding up, the AV holding its speed."""
    for column in range(1, env.position.shape[1]):
        env.position[:, column] = env.position[:, 0] - column * (60.0 + VEHICLE_LENGTH_M)
    env.speed[:, 2:] = 10.0


def test_the_fuel_term_averages_every_follower_at_the_speeds_the_step_starts_from() -> None:
    """The steady test has every car at 20 m/s, where the AV's fuel is the mean and the speed
    before the step the speed after it: here the humans at 10 m/s speed up."""
    env = steady_env("accel", RewardWeights(0.0, 0.0, 0.2, 0.0, 0.0))
    spread_platoon(env)
    before = env.speed[:, 1:].copy()
    _, reward, *_ = env.step(np.zeros((2, 1)))
    accel = (env.speed[:, 1:] - before) / 0.1
    assert np.all(accel[:, 1:] > 0.5)  # the humans do speed up
    per_car = RAV4_2019.fuel_rate_gps(before, accel)
    np.testing.assert_allclose(reward, 1.0 - 0.2 * per_car.mean(axis=1))
    assert not np.allclose(per_car[:, 0], per_car.mean(axis=1), atol=0.01)


def test_the_acceleration_term_is_the_avs_own() -> None:
    """c1 a^2 with a the AV's applied acceleration (the humans behind accelerate otherwise)."""
    env = steady_env("accel", RewardWeights(0.1, 0.0, 0.0, 0.0, 0.0))
    spread_platoon(env)
    for _ in range(5):  # braking: the limiter's jerk limit lets it build over the steps
        before = env.speed[:, 1].copy()
        _, reward, *_ = env.step(np.full((2, 1), -1.0))
        av_accel = (env.speed[:, 1] - before) / 0.1
        np.testing.assert_allclose(reward, 1.0 - 0.1 * av_accel**2)
    assert np.all(av_accel < -1.0)


def test_an_acc_policys_speed_is_asked_around_the_plans_target_in_mph() -> None:
    """v_action = v_s + 20 mph x a, v_s the plan's target at the AV (m/s to mph), then the
    clip (the last second's mean speed -15/+5 mph): with a = 0 the sequencer is asked for the
    plan's target, not the clip's floor."""
    env = steady_env("acc", ONLY_GAP, envs=1)
    env.target_here[:] = 16.0  # 35.8 mph, inside the clip around 44.7 mph
    env.step(np.array([[0.0, 0.0]]))
    assert env.cars[0].sequencer.target_speed_mph == 36
