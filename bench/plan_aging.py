"""How a car should age a plan, measured on the real drives: shifted with the waves, or held.

    .venv/bin/python -m bench.plan_aging [--shared ../shared] [--latency 0]

The agent reads a plan published `age` seconds ago at x - wave_speed * age (docs/agent.md:
the waves it describes have travelled upstream since; wave speed -15 km/h by default,
SMOOTHFLEET_AGENT_WAVE_SPEED_MPS). docs/planner.md found that moving a whole speed level
upstream fits these drives worse than leaving it where it is, as their slowdowns stand. This
asks the same of the agent's lookup.

Every 20 s of each of the nine drives with their INRIX minutes, the recommended planner makes a
plan from the INRIX visible then (after `--latency` s) and the probe car's own pings of the
previous minute (the protocol of planner/evaluation.py). For each age, the plan is read where
the car is `age` s later, with the agent's lookup (`TargetProfile`) shifted by the default wave
speed and not shifted, against the car's mean speed over the following 10 s. Prints the mean
absolute error (m/s) of the lane's TSE and of its published target (linear between the
sub-segments' centres), pooled over the drives.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from app.seed import seed_corridor_document
from planner import LaneObservations, NoInrixEstimate, PlannerInputs, plan_speeds
from planner.evaluation import probe_pings
from planner.pipeline import parse_params
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from planner.recorded import CorridorFrame
from vehicle_agent.controllers import TargetProfile
from vehicle_agent.plan import DEFAULT_WAVE_SPEED_MPS

ROOT = Path(__file__).resolve().parents[1]
AGES_S = (30.0, 60.0, 120.0, 180.0)
DECISION_STEP_S = 20.0
TRUTH_WINDOW_S = 10.0
LANE_INDEX = 0  # the probe car's lane 1, as in planner/evaluation.py


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=ROOT.parent / "shared")
    parser.add_argument("--latency", type=float, default=0.0, help="INRIX delay (s)")
    args = parser.parse_args()
    params = parse_params(RECOMMENDED_PLANNER_PARAMS)

    frame = CorridorFrame.of(seed_corridor_document())
    grid = frame.grid

    # (profile, age, shifted) -> absolute errors over every drive's decisions
    errors: dict[tuple[str, float, bool], list[float]] = {
        (profile, age, shifted): []
        for profile in ("tse", "target")
        for age in AGES_S
        for shifted in (False, True)
    }
    decisions = 0
    for folder in sorted((args.shared / "data/trajectories_with_inrix").iterdir()):
        recorded = frame.load(folder)
        drive = recorded.drive
        last = float(drive.time_s[-1]) - max(AGES_S) - TRUTH_WINDOW_S
        for now_s in np.arange(
            float(drive.time_s[0]) + params.ping_window_s, last, DECISION_STEP_S
        ):
            x_seen, speed_seen = probe_pings(drive, now_s - params.ping_window_s, now_s, 1.0)
            pings = LaneObservations.from_pings(
                grid, np.full(len(x_seen), LANE_INDEX + 1), x_seen, speed_seen
            )
            visible = recorded.inrix.until(now_s - args.latency)
            inputs = PlannerInputs(grid, visible, pings, float(now_s))
            try:
                plan = plan_speeds(inputs, RECOMMENDED_PLANNER, params)
            except NoInrixEstimate:
                continue
            decisions += 1
            for age in AGES_S:
                later = (drive.time_s >= now_s + age) & (
                    drive.time_s < now_s + age + TRUTH_WINDOW_S
                )
                position = float(drive.x_m[later][0])
                truth = float(drive.speed_mps[later].mean())
                for shifted in (False, True):
                    shift = -DEFAULT_WAVE_SPEED_MPS * age if shifted else 0.0
                    if grid.cell_of(np.array([position + shift]))[0] < 0:
                        continue
                    for name, speeds in (("tse", plan.tse_mps), ("target", plan.target_mps)):
                        profile = TargetProfile(grid.center_x_m, speeds[LANE_INDEX], shift_m=shift)
                        errors[(name, age, shifted)].append(abs(profile.at(position) - truth))
    print(
        f"latency {args.latency:.0f} s, {decisions} plans, wave speed "
        f"{DEFAULT_WAVE_SPEED_MPS:.2f} m/s; MAE (m/s) against the car {TRUTH_WINDOW_S:.0f} s later"
    )
    print(f"{'plan age':>9s} {'TSE held':>9s} {'shifted':>9s} {'target held':>12s} {'shifted':>9s}")
    for age in AGES_S:
        cells = [
            float(np.mean(errors[(name, age, shifted)]))
            for name in ("tse", "target")
            for shifted in (False, True)
        ]
        print(f"{age:8.0f}s {cells[0]:9.3f} {cells[1]:9.3f} {cells[2]:12.3f} {cells[3]:9.3f}")


if __name__ == "__main__":
    main()
