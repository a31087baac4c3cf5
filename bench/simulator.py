"""Simulator speed: time steps per second for a 200-vehicle platoon over a whole real drive.

    .venv/bin/python -m bench.simulator [--drive PATH] [--vehicles 200] [--repeat 3]

(as a module, like the other benches)

Figures, each the best of --repeat runs:
- the vectorised simulator (sim.platoon) with 200 IDM humans behind the leader;
- the same with one AV running the agent's microaccel controller and the planner in the loop;
- the baseline, measured in the same run: the same model stepped vehicle by vehicle in plain
  Python (the object-per-vehicle way the paper's simulator runs at ~2,000 steps/s), whose
  result is checked to equal the vectorised one before it is timed.
Goal (issue 6): >= 20,000 steps/s for 200 vehicles.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from contract.idm import I24_IDM, MIN_MODEL_GAP_M, equilibrium_gap_m
from sim.av import agent_policy
from sim.drives import Drive, load_drive
from sim.plans import SimulatedPlanner
from sim.platoon import VEHICLE_LENGTH_M, platoon_roles, simulate_platoon

ROOT = Path(__file__).resolve().parents[1]
DRIVE = ROOT.parent / "shared/data/trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"


def loop_platoon(drive: Drive, followers: int) -> np.ndarray:
    """The same IDM platoon, one vehicle at a time in plain Python; final positions."""
    params = I24_IDM
    v0 = params.desired_speed_mps
    braking = 1.0 / (2.0 * math.sqrt(params.max_accel_mps2 * params.comfortable_decel_mps2))
    spacing = float(equilibrium_gap_m(params, float(drive.speed_mps[0]))) + VEHICLE_LENGTH_M
    x = [0.0] + [-spacing * i for i in range(1, followers + 1)]
    v = [float(drive.speed_mps[0])] * (followers + 1)
    lead_x = drive.position_m.tolist()
    lead_v = drive.speed_mps.tolist()
    dt = drive.dt_s
    for k in range(drive.steps):
        accel = []
        for i in range(1, followers + 1):
            gap = max(x[i - 1] - x[i] - VEHICLE_LENGTH_M, MIN_MODEL_GAP_M)
            desired = (
                params.min_gap_m
                + v[i] * params.time_gap_s
                + max(0.0, v[i] * (v[i] - v[i - 1])) * braking
            )
            a = params.max_accel_mps2 * (1.0 - (v[i] / v0) ** 4 - (desired / gap) ** 2)
            accel.append(max(a, -v[i] / dt))
        for i in range(1, followers + 1):
            a = accel[i - 1]
            x[i] += v[i] * dt + 0.5 * a * dt * dt
            v[i] = max(v[i] + a * dt, 0.0)
        x[0] = lead_x[k + 1]
        v[0] = lead_v[k + 1]
    return np.array(x)


def best_seconds(run: Callable[[], object], repeat: int) -> float:
    """The fastest of `repeat` timed runs (the machine is shared)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drive", type=Path, default=DRIVE)
    parser.add_argument("--vehicles", type=int, default=200)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    drive = load_drive(args.drive)
    followers = args.vehicles
    humans = platoon_roles(humans=followers, avs=0)

    vectorised = simulate_platoon(drive, humans)
    looped = loop_platoon(drive, followers)
    error = float(np.abs(vectorised.position_m[-1] - looped).max())
    if error > 1e-6:
        raise SystemExit(f"the loop baseline disagrees with the simulator by {error:.2e} m")

    steps = drive.steps
    t_vector = best_seconds(lambda: simulate_platoon(drive, humans), args.repeat)

    def with_av() -> None:
        planner = SimulatedPlanner.for_drive(drive, "kernel_smooth")
        policy = agent_policy("microaccel", "accel", planner)
        simulate_platoon(drive, platoon_roles(humans=followers - 1, avs=1), [policy])

    t_av = best_seconds(with_av, args.repeat)
    t_loop = best_seconds(lambda: loop_platoon(drive, followers), 1)

    print(f"drive {drive.name}: {steps} steps ({drive.duration_s:.0f} s at 10 Hz)")
    print(f"platoon: leader + {followers} vehicles; loop baseline agrees to {error:.1e} m")
    print(f"vectorised, all human      : {steps / t_vector:10,.0f} steps/s")
    print(f"vectorised, 1 AV + planner : {steps / t_av:10,.0f} steps/s")
    print(f"baseline, per-vehicle loop : {steps / t_loop:10,.0f} steps/s")
    print(f"speed-up vs baseline       : {t_loop / t_vector:10.1f}x (all human)")
    for label, seconds in (("all human", t_vector), ("1 AV + planner", t_av)):
        verdict = "met" if steps / seconds >= 20_000 else "NOT met"
        print(f"goal >= 20,000 steps/s     : {verdict} ({label})")


if __name__ == "__main__":
    main()
