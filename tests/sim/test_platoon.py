"""The platoon simulator: waves grow behind a real stop-and-go leader, not behind a steady one,
and unsafe driving is reported, never hidden."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from contract.idm import I24_IDM, equilibrium_gap_m, idm_accel
from sim.drives import Drive, drive_from_speeds, load_drive
from sim.kpi import platoon_kpis
from sim.platoon import (
    VEHICLE_LENGTH_M,
    AvObservation,
    CutIns,
    HandBack,
    PlatoonRun,
    gap_events,
    platoon_roles,
    roles_for_penetration,
    simulate_platoon,
)

STOP_AND_GO = "trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"


def dip(base: float, low: float, seconds: float = 300.0) -> np.ndarray:
    """A leader at `base` that slows to `low` once (over about 20 s), then recovers."""
    t = np.arange(0.0, seconds, 0.1)
    bump = np.exp(-(((t - 60.0) / 10.0) ** 2))
    return base - (base - low) * bump


class Constant:
    """An AV that requests the same acceleration whatever happens (an unsafe controller)."""

    def __init__(self, accel: float) -> None:
        self.accel = accel
        self.seen: list[AvObservation] = []

    def accel_mps2(self, observation: AvObservation) -> float:
        self.seen.append(observation)
        return self.accel


def test_constant_speed_leader_makes_no_wave() -> None:
    leader = drive_from_speeds("steady", np.full(1200, 25.0))
    run = simulate_platoon(leader, platoon_roles(humans=24, avs=0))
    np.testing.assert_allclose(run.speed_mps, 25.0, atol=1e-9)
    gaps = run.gap_m
    np.testing.assert_allclose(gaps, float(equilibrium_gap_m(I24_IDM, 25.0)), atol=1e-6)
    assert run.collisions == 0
    assert run.gap_violations == 0


def test_string_unstable_platoon_grows_a_wave() -> None:
    # congested speeds, where the I-24 IDM is string-unstable
    leader = drive_from_speeds("dip", dip(10.0, 7.0))
    run = simulate_platoon(leader, platoon_roles(humans=24, avs=0))
    drop = 10.0 - run.speed_mps.min(axis=0)
    # the leader's 3 m/s dip deepens from car to car down the platoon
    assert drop[0] == pytest.approx(3.0)
    assert np.all(np.diff(drop) > 0)
    assert drop[-1] > 1.15 * drop[0]


def test_real_stop_and_go_drive_whole(shared_dir: Path) -> None:
    drive = load_drive(shared_dir / "data" / STOP_AND_GO)
    run = simulate_platoon(drive, platoon_roles(humans=24, avs=0))
    assert run.position_m.shape == (drive.steps + 1, 25)
    np.testing.assert_allclose(run.position_m[:, 0], drive.position_m)
    assert np.all(run.speed_mps >= 0.0)
    assert np.all(np.diff(run.position_m, axis=0) >= 0.0)
    # IDM humans behind a real leader: no crash, and the waves reach the tail stronger
    assert run.collisions == 0
    assert run.speed_mps[:, -1].std() > run.speed_mps[:, 0].std()


def test_followers_start_at_equilibrium_behind_the_leader() -> None:
    leader = drive_from_speeds("steady", np.full(20, 20.0))
    run = simulate_platoon(leader, platoon_roles(humans=3, avs=0))
    spacing = float(equilibrium_gap_m(I24_IDM, 20.0)) + VEHICLE_LENGTH_M
    np.testing.assert_allclose(run.position_m[0], [0.0, -spacing, -2 * spacing, -3 * spacing])


def test_av_observes_its_gap_and_leader_and_its_request_is_applied() -> None:
    leader = drive_from_speeds("steady", np.full(11, 20.0))
    policy = Constant(0.5)
    run = simulate_platoon(leader, platoon_roles(humans=2, avs=1), [policy])
    first = policy.seen[0]
    assert first.speed_mps == 20.0
    assert first.lead_speed_mps == 20.0
    assert first.gap_m == pytest.approx(float(equilibrium_gap_m(I24_IDM, 20.0)))
    assert [o.time_s for o in policy.seen[:3]] == pytest.approx([0.0, 0.1, 0.2])
    # 10 steps of 0.5 m/s^2
    assert run.speed_mps[-1, 1] == pytest.approx(20.5)
    np.testing.assert_allclose(run.accel_mps2[:-1, 1], 0.5)


def test_collision_is_recorded_not_clipped() -> None:
    leader = drive_from_speeds("brake", np.concatenate([np.full(50, 20.0), np.zeros(300)]))
    reckless = Constant(0.0)  # never brakes
    run = simulate_platoon(leader, platoon_roles(humans=1, avs=1), [reckless])
    assert run.collisions >= 1
    crash = next(event for event in run.events if event.kind == "collision")
    assert crash.vehicle == 1
    assert crash.min_gap_m < -10.0  # it drove on through the leader: nothing was clipped
    assert 0.5 < crash.first_time_s < 10.0


def test_gap_violation_without_contact_is_reported() -> None:
    leader = drive_from_speeds("steady", np.full(400, 10.0))

    class Tailgater:
        def accel_mps2(self, observation: AvObservation) -> float:
            # an overdamped gap controller aiming at 0.5 m behind the leader
            closing = observation.lead_speed_mps - observation.speed_mps
            return 0.2 * (observation.gap_m - 0.5) + 1.0 * closing

    run = simulate_platoon(leader, platoon_roles(humans=0, avs=1), [Tailgater()])
    assert run.collisions == 0
    assert run.gap_violations == 1
    assert 0.0 < run.events[0].min_gap_m < 1.0


def test_av_placement_by_penetration() -> None:
    roles = roles_for_penetration(25, 0.08)
    assert roles.sum() == 2
    assert roles[0]
    assert platoon_roles(humans=24, avs=1).tolist() == [True] + [False] * 24
    assert roles_for_penetration(25, 0.0).sum() == 0
    with pytest.raises(ValueError, match="between 0 and 1"):
        roles_for_penetration(25, 1.5)


def test_policy_count_must_match_the_avs() -> None:
    leader = drive_from_speeds("steady", np.full(20, 20.0))
    with pytest.raises(ValueError, match="2 AVs in the platoon but 1 policies"):
        simulate_platoon(leader, platoon_roles(humans=2, avs=2), [Constant(0.0)])


def test_non_finite_request_is_refused() -> None:
    leader = drive_from_speeds("steady", np.full(20, 20.0))
    with pytest.raises(ValueError, match="non-finite"):
        simulate_platoon(leader, platoon_roles(humans=0, avs=1), [Constant(float("nan"))])


class Supervised(Constant):
    """A constant request the simulator may hand back to a driver, as the agent does."""

    braking_authority_mps2 = 3.0

    def __init__(self, accel: float) -> None:
        super().__init__(accel)
        self.driver_steps = 0

    def driver_drives(self, observation: AvObservation) -> None:
        self.driver_steps += 1


def queue_ahead() -> Drive:
    """28 m/s, then a stopped queue: the leader brakes at 8 m/s^2, near the tyres' limit, to a
    stand. (It once stopped within a second, 28 m/s^2, which no tyre gives: behind it at the
    IDM's 1.24 s no driver with a reaction time stops in time, human or AV.)"""
    return drive_from_speeds(
        "queue", np.concatenate([np.full(200, 28.0), np.linspace(28.0, 0.0, 36), np.zeros(600)])
    )


def test_a_stop_beyond_the_authority_is_handed_back_and_the_driver_stops_in_time() -> None:
    reckless = Supervised(0.0)  # a stale plan: holds 28 m/s whatever it sees
    run = simulate_platoon(
        queue_ahead(), platoon_roles(humans=3, avs=1), [reckless], hand_back=HandBack()
    )
    assert run.collisions == 0
    assert run.takeovers == 1
    assert reckless.driver_steps > 0
    assert run.driver_seconds == pytest.approx(reckless.driver_steps * 0.1)
    # the same policy unsupervised drives into the queue
    unsupervised = simulate_platoon(queue_ahead(), platoon_roles(humans=3, avs=1), [Constant(0.0)])
    assert unsupervised.collisions >= 1


def test_the_driver_brakes_hard_only_after_the_reaction_time_the_stock_acc_before() -> None:
    def braking_times(reaction_time_s: float) -> tuple[float, float]:
        run = simulate_platoon(
            queue_ahead(),
            platoon_roles(humans=0, avs=1),
            [Supervised(0.0)],  # holds 28 m/s until it is handed back
            hand_back=HandBack(reaction_time_s=reaction_time_s),
        )
        assert run.takeovers == 1
        assert run.collisions == 0
        accel = np.diff(run.speed_mps[:, 1]) / run.dt_s
        handed_back = run.time_s[np.flatnonzero(accel < -0.01)[0]]
        beyond_acc = run.time_s[np.flatnonzero(accel < -3.5 - 1e-9)[0]]
        return float(handed_back), float(beyond_acc)

    handed_back, beyond_acc = braking_times(1.25)
    # the stock ACC's 3.5 m/s^2 until the driver reacts, 12 or 13 steps of 0.1 s later
    assert 1.2 - 1e-9 <= beyond_acc - handed_back <= 1.3 + 1e-9
    # a driver without one brakes harder half a second after the hand-back
    instant_handed_back, instant_beyond_acc = braking_times(0.0)
    assert instant_beyond_acc - instant_handed_back == pytest.approx(0.5)
    with pytest.raises(ValueError, match="reaction time 5.0 s"):
        HandBack(reaction_time_s=5.0)


def test_the_agent_takes_over_again_once_calm() -> None:
    leader = drive_from_speeds(
        "stop-and-go",
        np.concatenate(
            [
                np.full(200, 28.0),
                np.linspace(28.0, 0.0, 10),
                np.zeros(300),
                np.linspace(0.0, 20.0, 200),
                np.full(600, 20.0),
            ]
        ),
    )
    policy = Supervised(0.0)
    run = simulate_platoon(leader, platoon_roles(humans=0, avs=1), [policy], hand_back=HandBack())
    assert run.takeovers == 1
    # the driver hands control back to the agent, which then holds its speed (a = 0) to the end
    assert policy.seen[-1].time_s == pytest.approx(run.time_s[-2])
    assert run.speed_mps[-1, 1] == pytest.approx(run.speed_mps[-50, 1])


def test_a_policy_without_a_driver_cannot_be_supervised() -> None:
    leader = drive_from_speeds("steady", np.full(20, 20.0))
    with pytest.raises(ValueError, match="cannot be handed back"):
        simulate_platoon(
            leader, platoon_roles(humans=0, avs=1), [Constant(0.0)], hand_back=HandBack()
        )


class DropBack(Supervised):
    """An AV that falls back to 15 m/s and holds it: its gap grows by 10 m every second."""

    def accel_mps2(self, observation: AvObservation) -> float:
        return 0.5 * (15.0 - observation.speed_mps)


STEADY_LEADER = drive_from_speeds("steady", np.full(3000, 25.0))


def dropping_back(cut_ins: CutIns) -> PlatoonRun:
    """Two humans and an AV that drops back behind a leader at a steady 25 m/s."""
    return simulate_platoon(
        STEADY_LEADER, platoon_roles(humans=2, avs=1), [DropBack(0.0)], cut_ins=cut_ins
    )


def test_dropping_back_invites_cut_ins() -> None:
    run = dropping_back(CutIns(seed=1))
    assert run.cut_ins >= 2
    assert run.cut_in_position_m is not None
    # each merging car took the middle of the gap: the AV's gap halves (less a car length)
    first = int(np.argmax(np.isfinite(run.cut_in_position_m[:, 0])))
    before, after = run.gap_m[first - 1, 0], run.gap_m[first, 0]
    assert after == pytest.approx((before - VEHICLE_LENGTH_M) / 2, abs=1.0)
    assert run.collisions == 0
    # the same seed gives the same merges; no rate, no merges
    assert dropping_back(CutIns(seed=1)).cut_ins == run.cut_ins
    assert dropping_back(CutIns(rate_per_s_per_s=0.0)).cut_ins == 0


def test_each_gap_is_paired_with_the_speed_of_the_car_it_is_to() -> None:
    """After a cut-in the AV follows the car that merged, not its old leader: the time to
    collision must divide its gap by the closing speed on that car."""
    run = dropping_back(CutIns(seed=1))
    assert run.cut_in_position_m is not None
    assert run.cut_in_speed_mps is not None
    first = int(np.argmax(np.isfinite(run.cut_in_position_m[:, 0])))
    av = int(np.flatnonzero(run.is_av)[0])
    # before the merge: the car ahead in the platoon; from it on: the merged car
    np.testing.assert_array_equal(run.lead_speed_mps[:first, av - 1], run.speed_mps[:first, av - 1])
    assert run.lead_speed_mps[first, av - 1] == run.cut_in_speed_mps[first, 0]
    assert run.lead_speed_mps[first, av - 1] != run.speed_mps[first, av - 1]


def test_the_gaps_of_cars_that_merged_in_are_recorded_and_count_in_the_safety_kpis() -> None:
    """A car that merged in drives a gap like any follower: a collision of its own, its least
    gap and its time to collision must count, or a controller that invites cut-ins hides them."""
    run = dropping_back(CutIns(seed=1))
    assert run.cut_in_position_m is not None
    assert run.cut_in_gap_m is not None
    assert run.cut_in_speed_mps is not None
    assert run.cut_in_lead_speed_mps is not None
    first = int(np.argmax(np.isfinite(run.cut_in_position_m[:, 0])))
    # NaN until it merged; then its gap to the leader it took (the platoon's leader here)
    assert np.isnan(run.cut_in_gap_m[:first, 0]).all()
    expected = run.position_m[first:, 0] - run.cut_in_position_m[first:, 0] - VEHICLE_LENGTH_M
    np.testing.assert_allclose(run.cut_in_gap_m[first:, 0], expected)
    np.testing.assert_array_equal(run.cut_in_lead_speed_mps[first:, 0], run.speed_mps[first:, 0])
    assert run.every_gap_m.shape[1] == run.gap_m.shape[1] + run.cut_ins
    # the least gap is a merged car's once it is the least: here the platoon's is 20.9 m
    # (a follower's), so a merged car's 2 m must be what the KPI reads
    closer = run.cut_in_gap_m.copy()
    closer[first + 5, 0] = 2.0
    kpis = platoon_kpis(replace(run, cut_in_gap_m=closer))
    assert float(np.nanmin(run.gap_m)) > 20.0
    assert kpis.min_gap_m == pytest.approx(2.0)
    # a car that merged in and came within the violation distance has its own event, numbered
    # after the platoon's followers (the merged cars keep at least 31 m here, so 32 m is
    # crossed only by the one whose least gap is 31.3 m and by the followers)
    strict = simulate_platoon(
        STEADY_LEADER,
        platoon_roles(humans=2, avs=1),
        [DropBack(0.0)],
        cut_ins=CutIns(seed=1),
        gap_violation_m=32.0,
    )
    followers = strict.gap_m.shape[1]
    merged_events = [event for event in strict.events if event.vehicle > followers]
    assert len(merged_events) == 1
    assert merged_events[0].kind == "gap_violation"
    # an event per car that came too close, a merged car's numbered after the platoon's
    nan = np.nan
    gaps = np.array([[30.0, nan], [20.0, 6.0], [25.0, -0.2], [25.0, 1.0]])
    (event,) = gap_events(gaps, 0.1, 2.0)
    assert (event.kind, event.vehicle, event.first_time_s) == ("collision", 2, pytest.approx(0.2))


def test_cut_in_hazard_hand_worked() -> None:
    model = CutIns()
    # 25 m/s with 119 m: (119 - 19) / 25 = 4 s, 1 s beyond the threshold: 0.1 merges per
    # second; 94 m: 3 s, not beyond; 5 m/s with 30 m: 2.2 s; no room for a car; a standing queue
    hazard = model.hazard_per_s(
        np.array([119.0, 94.0, 30.0, 15.0, 30.0]), np.array([25.0, 25.0, 5.0, 3.0, 0.5])
    )
    np.testing.assert_allclose(hazard, [0.1, 0.0, 0.0, 0.0, 0.0], atol=1e-12)


class PostedLimit:
    """A posted limit of `limit_mps` everywhere."""

    def __init__(self, limit_mps: float) -> None:
        self.limit_mps = limit_mps

    def limits_mps(self, position_m: np.ndarray) -> np.ndarray:
        return np.full(np.shape(position_m), self.limit_mps)


def test_every_follower_drives_the_contracts_idm_with_its_delta_under_a_posted_limit() -> None:
    """The platoon writes the IDM out in place (for speed); it must be `contract.idm`'s, with the
    parameters' delta for humans and for the AV's free-road term alike (that term was written
    with delta 4 whatever the parameters said)."""
    idm = replace(I24_IDM, delta=2.0)
    limit = PostedLimit(24.0)
    leader = drive_from_speeds("steady", np.full(50, 20.0))
    greedy = Constant(3.0)  # more than the free-road term allows near the limit
    run = simulate_platoon(
        leader, platoon_roles(humans=3, avs=1), [greedy], idm=idm, speed_limit=limit
    )
    step = 10
    gaps = run.gap_m[step]
    speeds = run.speed_mps[step, 1:]
    expected = idm_accel(
        idm, gaps, speeds, run.lead_speed_mps[step], desired_speed_mps=np.full(4, 24.0)
    )
    av = int(np.flatnonzero(platoon_roles(humans=3, avs=1))[0])
    free_road = idm.max_accel_mps2 * (1.0 - (speeds[av] / 24.0) ** idm.delta)
    expected[av] = min(3.0, free_road)
    np.testing.assert_allclose(run.accel_mps2[step, 1:], expected, rtol=1e-9, atol=1e-9)
