"""A simulated corridor run written in the MOTION format and read back by the importer."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from app.motion.importer import import_motion_file
from app.motion.store import connect
from sim.drives import drive_from_speeds
from sim.motion.frame import MotionFrame
from sim.motion.traffic import (
    MOTION_STEP_S,
    MotionRunConfig,
    SimulatedTrajectory,
    boundary_speeds,
    simulate_motion_run,
)
from sim.motion.write import write_motion_json

CONFIG = MotionRunConfig(
    start_unix_s=1_668_600_000.0,
    duration_s=120.0,
    section_start_m=6000.0,
    section_length_m=1500.0,
    lanes=2,
    demand_veh_per_h_per_lane=1800.0,
    fleet_share=0.2,
    seed=3,
)


def _run(boundary_mps: float, config: MotionRunConfig = CONFIG) -> list[SimulatedTrajectory]:
    steps = int(config.duration_s / MOTION_STEP_S)
    return list(simulate_motion_run(config, np.full(steps, boundary_mps)))


def test_every_vehicle_drives_forward_in_its_lane_inside_the_section() -> None:
    trajectories = _run(30.0)
    assert len(trajectories) > 60  # about 2 lanes x 1800 veh/h x 2 min = 120 arrivals
    assert {t.lane for t in trajectories} == {1, 2}
    assert any(t.is_fleet for t in trajectories)
    for trajectory in trajectories:
        assert np.all(np.diff(trajectory.x_m) >= 0)
        assert trajectory.x_m[0] == pytest.approx(6000.0)  # every vehicle enters upstream
        assert np.all((trajectory.x_m >= 6000.0) & (trajectory.x_m < 7500.0))


def test_followers_never_overlap_their_leader() -> None:
    trajectories = _run(5.0)  # traffic crawls downstream: a queue forms in the section
    for lane in (1, 2):
        in_lane = sorted((t for t in trajectories if t.lane == lane), key=lambda t: t.first_unix_s)
        for leader, follower in zip(in_lane, in_lane[1:], strict=False):
            common_start = max(leader.first_unix_s, follower.first_unix_s)
            lead_at = int(round((common_start - leader.first_unix_s) / MOTION_STEP_S))
            follow_at = int(round((common_start - follower.first_unix_s) / MOTION_STEP_S))
            steps = min(len(leader.x_m) - lead_at, len(follower.x_m) - follow_at)
            lead = leader.x_m[lead_at : lead_at + steps]
            gaps = lead - follower.x_m[follow_at : follow_at + steps]
            assert np.all(gaps > leader.length_ft * 0.3048)


def _speed_near_the_end(trajectories: list[SimulatedTrajectory], end_m: float) -> float:
    """Mean speed over the section's last 200 m."""
    speeds = [np.diff(t.x_m)[t.x_m[:-1] > end_m - 200.0] / MOTION_STEP_S for t in trajectories]
    return float(np.concatenate(speeds).mean())


def test_a_slow_downstream_slows_the_section() -> None:
    # Traffic moving at 5 m/s past the end queues back into a short section within minutes.
    short = replace(CONFIG, section_length_m=600.0, duration_s=180.0)
    end = short.section_start_m + short.section_length_m
    slow = _speed_near_the_end(_run(5.0, short), end)
    assert slow < 0.5 * _speed_near_the_end(_run(30.0, short), end)


def test_the_written_file_imports_point_for_point(tmp_path: Path) -> None:
    trajectories = _run(30.0)
    path = tmp_path / "run.json"
    documents, points = write_motion_json(path, trajectories, MotionFrame(), run_id=7)
    assert (documents, points) == (len(trajectories), sum(len(t.x_m) for t in trajectories))
    report = import_motion_file(path, tmp_path / "store")
    assert (report.documents, report.points, report.bad) == (documents, points, [])
    with connect(tmp_path / "store") as connection:
        row = connection.execute(
            "SELECT count(*) FILTER (WHERE is_fleet), min(first_x_m), max(lane)"
            " FROM motion_trajectories"
        ).fetchone()
    assert row is not None
    assert row[0] == sum(t.is_fleet for t in trajectories)
    assert row[1] == pytest.approx(6000.0, abs=0.01)  # 0.01 ft rounding in the file
    assert row[2] == 2


@pytest.mark.parametrize("duration_s", [0.0, -5.0, float("nan"), float("inf")])
def test_a_run_of_no_time_is_refused_by_name(duration_s: float) -> None:
    """It ended in numpy's "need at least one array to concatenate" (or a NaN conversion)."""
    with pytest.raises(ValueError, match="duration_s must be finite and above 0"):
        boundary_speeds([drive_from_speeds("d", np.full(100, 20.0))], duration_s)
    with pytest.raises(ValueError, match="duration_s and section_length_m must be finite"):
        replace(CONFIG, duration_s=duration_s)
    with pytest.raises(ValueError, match="demand_veh_per_h_per_lane must be finite"):
        replace(CONFIG, demand_veh_per_h_per_lane=duration_s)
