"""The diagnosis of an RL policy: the envelope on a run worked by hand, the safety bound's share."""

from __future__ import annotations

import numpy as np
import pytest

from contract.controllers import SimpleParams
from sim.gaps import GapBounds
from sim.platoon import PlatoonRun
from sim.rl.diagnose import RecordingController, diagnose_first_follower, safety_bound_share
from vehicle_agent.controllers import AccelCommand, Observation
from vehicle_agent.controllers.simple import SimpleController


def test_each_moment_outside_is_counted_once_under_its_cause() -> None:
    # 10 rows, 0.1 s apart, vehicles 5 m long: the AV's gap (leader - AV - 5 m) by row
    gaps = np.array([50.0, 5.0, 5.0, 130.0, 110.0, 90.0, 105.0, 15.0, 60.0, 60.0])
    speeds = np.array([20.0, 20.0, 20.0, 20.0, 20.0, 20.0, 20.0, 20.0, 20.0, 21.0])
    leader = np.arange(10) * 2.0 + 1000.0
    run = PlatoonRun(
        drive_name="hand",
        dt_s=0.1,
        is_av=np.array([False, True]),
        position_m=np.column_stack([leader, leader - 5.0 - gaps]),
        speed_mps=np.column_stack([np.full(10, 20.0), speeds]),
        vehicle_length_m=5.0,
        gap_violation_m=0.0,
    )
    seen = diagnose_first_follower(run, GapBounds(min_gap_m=7.0, max_gap_m=120.0))
    assert seen.under_min_gap == pytest.approx(0.2)  # rows 1, 2 (5 m)
    assert seen.over_max_gap == pytest.approx(0.1)  # row 3 (130 m)
    assert seen.under_time_gap == pytest.approx(0.1)  # row 7 (15 m at 20 m/s = 0.75 s)
    assert seen.within == pytest.approx(0.6)
    # beyond the radar's 100 m: rows 3, 4 then 6, two separate episodes
    assert seen.leader_lost == pytest.approx(0.3)
    assert seen.leader_lost_episodes == 2
    assert seen.mean_gap_m == pytest.approx(63.0)
    # one change of 1 m/s in 0.1 s over 9 differences: sqrt(100 / 9)
    assert seen.accel_rms_mps2 == pytest.approx(np.sqrt(100.0 / 9.0))


def test_the_safety_bound_share_counts_the_commands_a_safe_lowered() -> None:
    commands = [
        AccelCommand(-0.5, requested_accel_mps2=0.6),  # a_safe lowered it
        AccelCommand(0.2, requested_accel_mps2=0.6),  # lowered
        AccelCommand(0.6, requested_accel_mps2=0.6),  # the network's own
        AccelCommand(-1.0, requested_accel_mps2=-1.0),  # the network's own braking
    ]
    seen = safety_bound_share(commands)
    assert seen.bound_share == pytest.approx(0.5)
    assert seen.request_mean_mps2 == pytest.approx(0.2)
    assert seen.request_p5_mps2 == pytest.approx(np.percentile([0.6, 0.6, 0.6, -1.0], 5.0))
    assert seen.request_p95_mps2 == pytest.approx(0.6)
    assert (seen.margin_mean_s, seen.margin_p95_s) == (0.0, 0.0)  # a plain request's
    margins = [AccelCommand(0.0, requested_accel_mps2=0.0, time_margin_s=h) for h in (0.5, 1.5)]
    assert safety_bound_share(margins).margin_mean_s == pytest.approx(1.0)
    with pytest.raises(ValueError, match="must carry the policy's request"):
        safety_bound_share([AccelCommand(0.1)])


def test_the_recording_controller_passes_actions_through_and_keeps_them() -> None:
    inner = SimpleController("accel", SimpleParams())
    recording = RecordingController(inner)
    observation = Observation(time_s=0.0, speed_mps=20.0, target_speed_mps=22.0)
    action = recording.step(observation)
    assert action == inner.step(observation)
    assert recording.actions == [action]
    assert recording.actuation == "accel"
