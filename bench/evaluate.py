"""How long the candidate evaluation takes: every shared drive x every registered pair.

    .venv/bin/python -m bench.evaluate [--drives DIR] [--workers N]

(as a module: run as a script, this file would shadow the `sim` package)

Figures, measured in one run:
- the evaluation `smoothfleet sim evaluate` runs by default on the 32 drives of
  ../shared/data/trajectories (shockwave and freeflow cases, both planners, every registered
  controller and the recommended variant, 1 AV), wall time and CPU time of all processes;
- the baseline: the all-human platoons of the same cases alone (the floor any evaluation pays).
The machine's load average is printed beside them: on a shared machine wall time is not the
program's alone. Goal (issue 12): the evaluation in under 5 minutes.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

from planner import ALGORITHMS
from sim.drives import load_drives, shared_data_dir
from sim.evaluate import default_workers, evaluate
from sim.recommended import RECOMMENDED_PLANNER_PARAMS, registered_variants
from sim.scenarios import scenario_cases


def cpu_seconds() -> float:
    """User + system time of this process and its finished children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=Path, default=None)
    parser.add_argument("--workers", type=int, default=default_workers())
    args = parser.parse_args()
    drives = load_drives(args.drives or shared_data_dir() / "trajectories")
    cases = scenario_cases(["shockwave", "freeflow"], drives)
    variants = registered_variants()
    planners = ALGORITHMS.names()
    print(
        f"{len(drives)} drives, {len(cases)} cases, {len(planners)} planners x "
        f"{len(variants)} controllers, {args.workers} workers, load average "
        f"{os.getloadavg()[0]:.1f} at start"
    )

    start, cpu = time.perf_counter(), cpu_seconds()
    baseline = evaluate(cases, planners[:1], [], workers=args.workers)
    base_wall, base_cpu = time.perf_counter() - start, cpu_seconds() - cpu
    print(
        f"baseline, all-human runs only : {len(baseline.results):4d} runs in "
        f"{base_wall:7.1f} s wall, {base_cpu:7.1f} s CPU"
    )

    start, cpu = time.perf_counter(), cpu_seconds()
    full = evaluate(
        cases,
        planners,
        variants,
        planner_params=RECOMMENDED_PLANNER_PARAMS,
        workers=args.workers,
    )
    wall, used = time.perf_counter() - start, cpu_seconds() - cpu
    print(
        f"evaluation, registered pairs   : {len(full.results):4d} runs in {wall:7.1f} s wall, "
        f"{used:7.1f} s CPU ({1000 * used / len(full.results):.0f} ms CPU a run)"
    )
    print(f"load average at the end        : {os.getloadavg()[0]:.1f}")
    print(f"goal: under 300 s wall         : {'met' if wall < 300 else 'NOT met'}")


if __name__ == "__main__":
    main()
