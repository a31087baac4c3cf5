"""Drives recorded with their real INRIX minutes: the feed placed along the drive, read by the
planner in the loop as it arrived."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from contract.recorded import InrixMinutes, read_trajectory
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import DriveError
from sim.evaluate import ControllerVariant, run_case
from sim.plans import NoPlanHeld, SimulatedPlanner
from sim.recorded import feed_in_drive_frame, load_recorded_drives
from sim.scenarios import Case, scenario_cases
from vehicle_agent.plan import DEFAULT_WAVE_SPEED_MPS


def test_feed_positions_count_from_the_drives_start() -> None:
    recording = InrixMinutes(
        segment_start_m=np.array([0.0, 800.0, 1800.0]),
        time_s=np.array([-60.0, 0.0]),
        speed_mps=np.array([[30.0, 20.0, 10.0], [30.0, 20.0, 10.0]]),
        score=np.full((2, 3), 30.0),
        c_value=np.full((2, 3), 0.9),
    )
    # the drive starts 1000 m along the reference line
    feed = feed_in_drive_frame(recording, 1000.0)
    np.testing.assert_allclose(feed.segment_start_m, [-1000.0, -200.0, 800.0])
    # the last segment's end is not recorded: it gets the median length, 900 m
    np.testing.assert_allclose(feed.segment_end_m, [-200.0, 800.0, 1700.0])
    # each minute reaches the planner when it was received
    assert feed.visible_rows(-0.1).tolist() == [True, False]


# The two recordings first shared.
FIRST_SHARED = (
    "2021-03-15-12-46-38_2T3MWRFVXLW056972_masterArray_0_4917",
    "2021-04-22-12-47-13_2T3MWRFVXLW056972_masterArray_1_5292",
)


def test_the_shared_recordings(shared_dir: Path) -> None:
    recorded = load_recorded_drives(shared_dir / "data" / "trajectories_with_inrix")
    assert len(recorded) == 9
    by_name = {one.drive.name: one for one in recorded}
    for name in FIRST_SHARED:
        # both drives start by GPS ~780 m along the reference line, just before the segment
        # that begins at 824 m: it lies 40-50 m ahead of the drive's start
        assert 35.0 < by_name[name].feed.segment_start_m[4] < 55.0
    for one in recorded:
        # every recording starts inside the segment before that one (34-46 m short of it)
        assert one.feed.segment_start_m[3] < 0.0 < one.feed.segment_start_m[4] < 55.0
        assert one.feed.speed_mps.shape[1] == 21
    cases = scenario_cases(["shockwave_inrix"], [], recorded)
    # the longer cuts of 2021-03-08 never slow into a wave; the other seven do
    assert len(cases) == 7
    assert all(case.inrix is not None for case in cases)
    assert set(FIRST_SHARED) <= {case.drive.name for case in cases}
    # ...and they have a scenario of their own: every recording is in exactly one
    freeflow = scenario_cases(["freeflow_inrix"], [], recorded)
    assert sorted(case.drive.name[:21] for case in freeflow) == ["2021-03-08-22-35-14_2"] * 2
    assert all(case.inrix is not None for case in freeflow)
    both = {case.drive.name for case in cases + freeflow}
    assert both == {one.drive.name for one in recorded}


def test_the_planner_reads_the_recorded_minutes(shared_dir: Path) -> None:
    one = next(
        one
        for one in load_recorded_drives(shared_dir / "data" / "trajectories_with_inrix")
        if one.drive.name == FIRST_SHARED[0]
    )
    planner = SimulatedPlanner.for_drive(one.drive, "kernel_smooth_buffer", feed=one.feed)
    assert planner.feed is one.feed
    for time_s in np.arange(0.0, one.drive.duration_s, 60.0):
        planner.profile(float(time_s))
    # 2021-03-15: the real INRIX shows a standing slowdown (8-9 m/s over two segments), so the
    # buffer variant prescribes buffers in some of its plans
    assert planner.plans_run == 9
    assert planner.plans_buffered > 0


def test_cycles_without_inrix_are_skipped_and_a_stale_plan_is_dropped(shared_dir: Path) -> None:
    """As the server: a cycle whose newest INRIX is too old publishes nothing and the AVs keep
    their plan while it is fresh (180 s, the agent's default), then hold none (the agent hands
    the car back to its stock ACC: `sim.av`) until a plan is published again."""
    one = next(
        one
        for one in load_recorded_drives(shared_dir / "data" / "trajectories_with_inrix")
        if one.drive.name == FIRST_SHARED[0]
    )
    # the feed's minutes up to 2 minutes into the drive, as if the recording had stopped there
    kept = one.feed.measured_at_s <= 120.0
    assert one.feed.measured_at_s[kept][-1] == pytest.approx(89.3)
    cut = replace(
        one.feed, measured_at_s=one.feed.measured_at_s[kept], speed_mps=one.feed.speed_mps[kept]
    )
    planner = SimulatedPlanner.for_drive(one.drive, "kernel_smooth", feed=cut)
    planner.profile(0.0)
    held = planner.profile(660.0)  # 571 s after the last reading: within the 600 s limit
    assert held is not None
    assert (planner.plans_run, planner.plans_skipped) == (2, 0)
    planner.profile(720.0)  # 631 s: skipped, the 660 s plan held (fresh until 840 s)
    planner.profile(780.0)  # skipped likewise
    later = planner.profile(840.0)
    assert later is not None
    assert (planner.plans_run, planner.plans_skipped) == (2, 3)
    # the held plan, read 180 s later: the same targets, shifted by the agent's wave speed
    assert later.target_speed_mps.tolist() == held.target_speed_mps.tolist()
    assert later.shift_m - held.shift_m == pytest.approx(-DEFAULT_WAVE_SPEED_MPS * 180.0)
    # 180.1 s old: stale, and the feed never comes back
    assert planner.profile(840.1) is None
    assert planner.profile(900.0) is None
    assert planner.plans_skipped == 4
    with pytest.raises(NoPlanHeld, match=rf"{one.drive.name}: no fresh plan at 900 s \(2 publ"):
        planner.held_profile(900.0)
    # a feed that starts after the drive: no plan until its first minute has arrived
    late = replace(
        one.feed,
        measured_at_s=one.feed.measured_at_s[~kept],
        speed_mps=one.feed.speed_mps[~kept],
    )
    starved = SimulatedPlanner.for_drive(one.drive, "kernel_smooth", feed=late)
    first_seen_s = float(late.measured_at_s[0] + late.latency_s)
    assert starved.profile(0.0) is None
    first_cycle_s = 60.0 * np.ceil(first_seen_s / 60.0)
    assert starved.profile(first_cycle_s - 0.1) is None
    assert starved.profile(first_cycle_s) is not None
    assert starved.plans_run == 1


def test_an_evaluation_drives_without_a_plan_on_the_stock_acc(shared_dir: Path) -> None:
    """A recording whose INRIX begins after the drive is simulated, not refused: until the
    first plan every AV drives on its stock ACC, counted as a plan hand-back; then its
    controller takes over, and nobody collides."""
    one = next(
        one
        for one in load_recorded_drives(shared_dir / "data" / "trajectories_with_inrix")
        if one.drive.name == FIRST_SHARED[0]
    )
    late = one.feed.measured_at_s > 120.0
    assert one.feed.measured_at_s[late][0] == pytest.approx(149.3)
    cut = replace(
        one.feed, measured_at_s=one.feed.measured_at_s[late], speed_mps=one.feed.speed_mps[late]
    )
    case = Case("shockwave_inrix", one.drive, inrix=cut)
    for variant in ("microaccel:accel", "microaccel_acc:acc"):
        result = run_case(
            case,
            RECOMMENDED_PLANNER,
            ControllerVariant.parse(variant),
            humans=22,
            avs=2,
            planner_params=RECOMMENDED_PLANNER_PARAMS,
        )
        assert result.kpis.collisions == 0, variant
        # the cycles at 0, 60 and 120 s find no INRIX; the one at 180 s publishes the first plan
        assert (result.plans_skipped, result.plans_run) == (3, 6), variant
        assert result.plan_hand_backs == 2, variant
        assert result.seconds_without_plan == pytest.approx(2 * 180.0), variant


def test_a_folder_without_recordings_is_named(tmp_path: Path) -> None:
    with pytest.raises(DriveError, match="no drive folders with INRIX recordings"):
        load_recorded_drives(tmp_path)


def without_gps_for_the_first(rows: int, source: Path, folder: Path) -> Path:
    """A copy of a recording whose first `rows` samples have no GPS fix (empty cells)."""
    shutil.copytree(source, folder)
    lines = (folder / "trajectory.csv").read_text().splitlines(keepends=True)
    header = lines[0].rstrip("\n").split(",")
    blank = [header.index("LatitudeGPS"), header.index("LongitudeGPS")]
    for number in range(1, rows + 1):
        cells = lines[number].split(",")
        for index in blank:
            cells[index] = ""
        lines[number] = ",".join(cells)
    (folder / "trajectory.csv").write_text("".join(lines))
    return folder.parent


def test_a_recording_that_begins_before_its_first_fix_is_placed_by_the_distance_driven(
    shared_dir: Path, tmp_path: Path
) -> None:
    source = shared_dir / "data" / "trajectories_with_inrix" / FIRST_SHARED[0]
    placed = load_recorded_drives(source.parent)
    (original,) = (one for one in placed if one.drive.name == FIRST_SHARED[0])
    trajectory = read_trajectory(source / "trajectory.csv")
    driven_m = np.cumsum(trajectory.speed_mps) * 0.1
    # no fix for the first 300 m: placed from the fix after them, within a few metres (GPS and
    # the integrated wheel speed differ by about 1 %)
    late_fix = int(np.searchsorted(driven_m, 300.0))
    moved = load_recorded_drives(
        without_gps_for_the_first(late_fix, source, tmp_path / "late" / source.name)
    )[0]
    np.testing.assert_allclose(moved.feed.segment_start_m, original.feed.segment_start_m, atol=5.0)
    np.testing.assert_array_equal(moved.drive.speed_mps, original.drive.speed_mps)
    # no fix for 1.1 km: where the drive began is no longer known
    no_fix = int(np.searchsorted(driven_m, 1100.0))
    with pytest.raises(DriveError, match="no GPS fix on the seed corridor within the drive's fi"):
        load_recorded_drives(
            without_gps_for_the_first(no_fix, source, tmp_path / "lost" / source.name)
        )
