"""KPIs on hand-built cases: two cars whose every number can be worked out on paper."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim.kpi import (
    accel_rms_mps2,
    change_pct,
    fuel_economy_mpg,
    fuel_saving_pct,
    jerk_rms_mps3,
    measurement_points_m,
    min_time_to_collision_s,
    network_speed_mps,
    platoon_kpis,
    shared_points_m,
    throughput_at_vph,
    throughput_vph,
)
from sim.platoon import PlatoonRun

# Two cars at 10 m/s, 15 m apart (front bumpers), for 2 s in steps of 1 s.
POSITIONS = np.array([[0.0, -15.0], [10.0, -5.0], [20.0, 5.0]])
SPEEDS = np.full((3, 2), 10.0)
# Fuel rate at 10 m/s, a = 0: C(10) = 0.295542696 g/s (see test_energy)
C_10 = 0.295542696


def test_fuel_economy_of_two_cruising_cars() -> None:
    # fuel: 2 cars x 2 s x 0.295542696 g/s = 1.182170784 g = 1.182170784 x 1.268 / 3600 gal
    #     = 4.1638682e-4 gal; distance: 2 x 20 m = 40 m = 0.024854848 mi
    # -> 59.691725 mpg
    assert fuel_economy_mpg(POSITIONS, SPEEDS, 1.0) == pytest.approx(59.691725, rel=1e-6)


def test_fuel_economy_counts_acceleration_over_its_step() -> None:
    # car A speeds up 10 -> 11 m/s over step 0 (a = 1), then cruises at 11; car B cruises at 10
    positions = np.array([[0.0, -15.0], [10.5, -5.0], [21.5, 5.0]])
    speeds = np.array([[10.0, 10.0], [11.0, 10.0], [11.0, 10.0]])
    # fuel: f(10, 1) + f(11, 0) + 2 f(10, 0)
    #     = 1.256577170 + 0.316801929 + 0.591085392 = 2.164464491 g = 7.6237249e-4 gal
    # distance: 21.5 + 20 = 41.5 m = 0.025786904 mi -> 33.824547 mpg
    assert fuel_economy_mpg(positions, speeds, 1.0) == pytest.approx(33.824547, rel=1e-6)


def test_throughput_of_two_cars_1_5_s_apart() -> None:
    # every point is crossed by the second car 1.5 s after the first: 1 / 1.5 s = 2400 veh/h
    assert throughput_at_vph(POSITIONS, 1.0, 2.0) == pytest.approx(2400.0)
    # the common stretch is 0..5 m; five equi-spaced interior points
    np.testing.assert_allclose(
        measurement_points_m(POSITIONS), [5 / 6, 10 / 6, 2.5, 20 / 6, 25 / 6]
    )
    assert throughput_vph(POSITIONS, 1.0) == pytest.approx(2400.0)


def test_a_car_stopped_at_the_point_counts_when_it_arrives_not_when_it_leaves() -> None:
    # the first car reaches 10 m at t = 1 s, waits there until t = 3 s, goes on; the second
    # reaches it at t = 4 s: a detector at 10 m counts them 3 s apart, 1200 veh/h (read from
    # its departure, 1 s apart: 3600)
    positions = np.array(
        [[0.0, -20.0], [10.0, -15.0], [10.0, -10.0], [10.0, -5.0], [20.0, 10.0], [30.0, 20.0]]
    )
    assert throughput_at_vph(positions, 1.0, 10.0) == pytest.approx(1200.0)


def test_throughput_refuses_a_point_not_every_car_reaches() -> None:
    with pytest.raises(ValueError, match="not every vehicle passes 12 m"):
        throughput_at_vph(POSITIONS, 1.0, 12.0)


def test_network_speed_is_total_distance_over_total_time() -> None:
    # one car stands still for 2 s, the other drives 20 m: 20 m / 4 s = 5 m/s
    positions = np.array([[0.0, -15.0], [10.0, -15.0], [20.0, -15.0]])
    assert network_speed_mps(positions, 1.0) == pytest.approx(5.0)
    assert network_speed_mps(POSITIONS, 1.0) == pytest.approx(10.0)


def test_comfort_acceleration_and_jerk() -> None:
    # accelerations per step: car A 1, -1; car B 0, 0 -> RMS sqrt(2/4) = 0.707107
    # jerk: car A (-1 - 1) / 1 s = -2, car B 0 -> RMS sqrt(4/2) = 1.414214
    speeds = np.array([[10.0, 10.0], [11.0, 10.0], [10.0, 10.0]])
    assert accel_rms_mps2(speeds, 1.0) == pytest.approx(np.sqrt(0.5))
    assert jerk_rms_mps3(speeds, 1.0) == pytest.approx(np.sqrt(2.0))
    assert accel_rms_mps2(SPEEDS, 1.0) == 0.0
    # at the simulator's 0.1 s: accelerations +1 and -1 m/s^2, jerk (-1 - 1) / 0.1 = -20 m/s^3
    fine = np.array([[10.0], [10.1], [10.0]])
    assert accel_rms_mps2(fine, 0.1) == pytest.approx(1.0)
    assert jerk_rms_mps3(fine, 0.1) == pytest.approx(20.0)


def test_time_to_collision_only_when_closing_in() -> None:
    gaps = np.array([[10.0], [8.0]])
    follower = np.array([[12.0], [10.0]])
    leader = np.array([[10.0], [10.0]])
    # closing at 2 m/s with 10 m left: 5 s; the second moment is not closing
    assert min_time_to_collision_s(gaps, follower, leader) == pytest.approx(5.0)
    assert min_time_to_collision_s(gaps, leader, follower) == float("inf")


def test_time_to_collision_of_a_car_creeping_closer_by_ulps_is_infinite() -> None:
    # a car that cannot accelerate closes in at 1e-320 m/s: 10 m / 1e-320 m/s overflows
    gaps = np.array([[10.0]])
    assert min_time_to_collision_s(gaps, np.array([[1e-320]]), np.array([[0.0]])) == float("inf")


def cruising_platoon(leader_ahead_m: float) -> PlatoonRun:
    """Leader, car A and car B at 10 m/s for 9 s; B 15 m behind A, the leader ahead of A."""
    time_s = np.arange(10.0)[:, None]
    fronts = np.array([[leader_ahead_m, 0.0, -15.0]])
    return PlatoonRun(
        drive_name="hand-built",
        dt_s=1.0,
        is_av=np.array([False, True, False]),
        position_m=fronts + 10.0 * time_s,
        speed_mps=np.full((10, 3), 10.0),
        vehicle_length_m=5.0,
        gap_violation_m=1.0,
    )


def test_platoon_kpis_count_the_leader_in_throughput_only() -> None:
    # the leader 15 m ahead of car A: 1.5 s ahead of it at every point, like car B behind A
    kpis = platoon_kpis(cruising_platoon(15.0))
    # fuel, speed and comfort over the two simulated cars (the leader's drive is the same in
    # every run): 2 cars x 9 s x C(10) over 2 x 90 m, the same ratio as the 2 s case above
    assert kpis.fuel_economy_mpg == pytest.approx(59.691725, rel=1e-6)
    assert kpis.network_speed_mps == pytest.approx(10.0)
    assert kpis.accel_rms_mps2 == 0.0
    # throughput over all three: 2 intervals of 1.5 s at every point -> 2400 veh/h
    assert kpis.throughput_vph == pytest.approx(2400.0)
    assert kpis.min_gap_m == pytest.approx(10.0)
    assert kpis.collisions == 0


def test_a_gap_opened_behind_the_leader_costs_throughput() -> None:
    # the same two cars, but the leader 45 m ahead of car A (4.5 s): crossings at 0, 4.5, 6 s
    # -> 2 intervals over 6 s = 1200 veh/h; without the leader it would still read 2400
    assert platoon_kpis(cruising_platoon(45.0)).throughput_vph == pytest.approx(1200.0)


def test_a_platoon_whose_tail_never_passes_the_leaders_start_has_no_throughput() -> None:
    # car B stalls 100 m behind car A and never moves: after 9 s it is at -100 m, short of
    # where the leader started (15 m); no point is crossed by all three during the run
    run = cruising_platoon(15.0)
    position = run.position_m.copy()
    position[:, 2] = -100.0
    speed = run.speed_mps.copy()
    speed[:, 2] = 0.0
    stalled = PlatoonRun(
        drive_name="hand-built",
        dt_s=1.0,
        is_av=run.is_av,
        position_m=position,
        speed_mps=speed,
        vehicle_length_m=5.0,
        gap_violation_m=1.0,
    )
    with pytest.raises(ValueError, match="share no stretch"):
        measurement_points_m(position)
    assert platoon_kpis(stalled).throughput_vph == 0.0
    assert platoon_kpis(stalled, throughput_points_m=np.array([20.0])).throughput_vph == 0.0


def test_a_car_that_merged_in_counts_where_it_crossed_in_the_lane() -> None:
    run = cruising_platoon(45.0)
    # a car merged into the 45 m gap at t = 2 s, 20 m behind the leader, at 10 m/s
    merged = np.full((10, 1), np.nan)
    merged[2:, 0] = (45.0 - 20.0) + 10.0 * np.arange(2.0, 10.0)
    points = measurement_points_m(run.position_m)
    # it crossed every point (45..75 m) in the lane: 3 intervals over 6 s = 1800 veh/h
    assert throughput_vph(run.position_m, 1.0, merged_m=merged) == pytest.approx(1800.0)
    # a point it had passed before merging does not see it
    early = np.full((10, 1), np.nan)
    early[8:, 0] = merged[8:, 0]
    assert throughput_at_vph(run.position_m, 1.0, float(points[0]), early) == pytest.approx(1200.0)


def test_fuel_saving_is_the_drop_in_fuel_per_distance_and_undefined_over_no_distance() -> None:
    # 40 mpg before, 44 after: 1 - 40/44 = 9.09 % less fuel per mile
    assert fuel_saving_pct(40.0, 44.0) == pytest.approx(100.0 / 11.0)
    assert fuel_saving_pct(44.0, 40.0) == pytest.approx(-10.0)
    # a platoon that never moved has 0 mpg either way (it divided by zero)
    assert math.isnan(fuel_saving_pct(0.0, 0.0))
    assert math.isnan(fuel_saving_pct(float("nan"), 40.0))


def test_a_kpi_change_against_a_baseline_of_zero_is_undefined() -> None:
    assert change_pct(1900.0, 2000.0) == pytest.approx(-5.0)
    assert math.isnan(change_pct(0.0, 0.0))  # the throughput of a platoon that never moved
    assert math.isnan(change_pct(float("inf"), 2.0))


def test_a_run_and_its_baseline_are_measured_at_the_same_road_locations() -> None:
    """The paper's five points are the road's: a platoon whose tail ends short of the other's
    is measured, with the other, over the stretch both tails reached."""
    ahead = cruising_platoon(45.0)
    behind_position = ahead.position_m.copy()
    behind_position[:, 2] -= 15.0  # its last car 15 m further back throughout
    points = shared_points_m([ahead.position_m, behind_position])
    first = float(ahead.position_m[0].max())
    last = float(behind_position[-1].min())
    np.testing.assert_allclose(points, np.linspace(first, last, 7)[1:-1])
    assert last < float(ahead.position_m[-1].min())  # not the points `ahead` alone would give
