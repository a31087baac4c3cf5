"""Scenarios: which real drives make which scenario, and the density-limited bottleneck."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sim.drives import drive_from_speeds, load_drives
from sim.kpi import platoon_kpis
from sim.platoon import platoon_roles, simulate_platoon
from sim.scenarios import Bottleneck, scenario_cases


def test_limit_is_capacity_over_density() -> None:
    region = Bottleneck(1000.0, 2000.0, capacity_vph=1800.0, free_speed_mps=30.0)
    # three cars 25 m apart inside: 2 / 50 m = 0.04 veh/m; 1800 veh/h = 0.5 veh/s -> 12.5 m/s
    positions = np.array([1500.0, 1475.0, 1450.0, 900.0])
    limits = region.limits_mps(positions)
    assert limits is not None
    np.testing.assert_allclose(limits, [12.5, 12.5, 12.5, np.inf])
    # sparse traffic is held to the free speed, not above it
    assert region.limit_for_density_mps(0.01) == 30.0
    # one car alone inside has no density to measure: the free speed
    one = region.limits_mps(np.array([1500.0, 900.0]))
    assert one is not None
    assert one[0] == 30.0
    assert region.limits_mps(np.array([900.0, 800.0])) is None
    assert region.measure_point_m == 2100.0


def test_bad_region_is_refused() -> None:
    with pytest.raises(ValueError, match="end after it starts"):
        Bottleneck(2000.0, 1000.0)


def test_bottleneck_queues_the_platoon_and_cuts_the_flow() -> None:
    leader = drive_from_speeds("fast", np.full(3000, 30.0))
    region = Bottleneck(3000.0, 4000.0, capacity_vph=1300.0)
    roles = platoon_roles(humans=24, avs=0)
    free = simulate_platoon(leader, roles)
    held = simulate_platoon(leader, roles, speed_limit=region)
    inside = (held.position_m[:, 1:] >= 3000.0) & (held.position_m[:, 1:] < 4000.0)
    assert held.speed_mps[:, 1:][inside].mean() < 15.0
    assert held.speed_mps[:, 0].min() == 30.0  # the replayed leader is not held
    point = np.array([region.measure_point_m])
    assert platoon_kpis(held, throughput_points_m=point).throughput_vph < 0.9 * (
        platoon_kpis(free, throughput_points_m=point).throughput_vph
    )
    assert held.collisions == 0


def test_scenarios_from_the_shared_drives(shared_dir: Path) -> None:
    drives = load_drives(shared_dir / "data" / "trajectories")
    cases = scenario_cases(["shockwave", "freeflow", "bottleneck"], drives)
    by_scenario: dict[str, int] = {}
    for case in cases:
        by_scenario[case.scenario] = by_scenario.get(case.scenario, 0) + 1
    assert by_scenario == {"shockwave": 20, "freeflow": 12, "bottleneck": 12}
    bottleneck = next(case for case in cases if case.bottleneck is not None)
    assert bottleneck.drive.kind == "freeflow"
    with pytest.raises(ValueError, match="unknown scenario rush"):
        scenario_cases(["rush"], drives)
