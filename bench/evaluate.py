"""How long the default candidate evaluation takes: `smoothfleet sim evaluate` with no flags.

    .venv/bin/python -m bench.evaluate [--workers N]

(as a module, like the other benches)

Figures, measured in one run:
- the baseline: the all-human platoons of every case alone (the floor any evaluation pays);
- the evaluation exactly as `smoothfleet sim evaluate` runs it without flags (every scenario on
  the shared data: the 32 drives' shockwave and freeflow cases, the bottleneck on the freeflow
  ones, the 9 drives recorded with their real INRIX; every planner x every registered controller
  and the recommended variant, 1 AV; its progress bar, table, CSV and heatmap), wall time and
  CPU time of all its processes.
The machine's load average is printed beside them: on a shared machine wall time is not the
program's alone. Goal (issue 12): the evaluation in under 5 minutes.
"""

from __future__ import annotations

import argparse
import os
import resource
import tempfile
import time
from pathlib import Path

from sim.drives import load_drives, shared_data_dir
from sim.evaluate import default_workers, evaluate
from sim.recorded import load_recorded_drives
from sim.scenarios import SCENARIOS, scenario_cases
from smoothfleet.cli.sim import evaluate_command


def cpu_seconds() -> float:
    """User + system time of this process and its finished children."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=default_workers())
    args = parser.parse_args()
    data = shared_data_dir()
    cases = scenario_cases(
        list(SCENARIOS),
        load_drives(data / "trajectories"),
        load_recorded_drives(data / "trajectories_with_inrix"),
    )
    print(
        f"{len(cases)} cases ({', '.join(SCENARIOS)}), {args.workers} workers, load average "
        f"{os.getloadavg()[0]:.1f} at start"
    )

    start, cpu = time.perf_counter(), cpu_seconds()
    baseline = evaluate(cases, [], [], workers=args.workers)
    base_wall, base_cpu = time.perf_counter() - start, cpu_seconds() - cpu
    print(
        f"baseline, all-human runs only : {len(baseline.results):4d} runs in "
        f"{base_wall:7.1f} s wall, {base_cpu:7.1f} s CPU"
    )

    with tempfile.TemporaryDirectory() as out:
        start, cpu = time.perf_counter(), cpu_seconds()
        evaluate_command.main(["--workers", str(args.workers), "--out", out], standalone_mode=False)
        wall, used = time.perf_counter() - start, cpu_seconds() - cpu
        with (Path(out) / "evaluation.csv").open() as handle:
            runs = sum(1 for _ in handle) - 1
    print(
        f"`smoothfleet sim evaluate`     : {runs:4d} runs in {wall:7.1f} s wall, "
        f"{used:7.1f} s CPU ({1000 * used / runs:.0f} ms CPU a run)"
    )
    print(f"load average at the end        : {os.getloadavg()[0]:.1f}")
    print(f"goal: under 300 s wall         : {'met' if wall < 300 else 'NOT met'}")


if __name__ == "__main__":
    main()
