"""Cost of the fuel-optimal bound (sim.optimum) per drive.

    .venv/bin/python -m bench.optimum [--drive PATH ...] [--repeat 5]

(as a module, like the other benches)

Figures per drive, wall and CPU seconds (the machine is shared: CPU time is the steadier one):
- the whole bound: baseline run, L-BFGS-B over the adjoint, verifying replay;
- one adjoint sweep (forward simulation + backward sweep, compiled), best of --repeat;
- the baseline, measured in the same run: one `simulate_platoon` of the same 26-vehicle
  platoon (all humans), best of --repeat, so the sweep and the bound read as "simulations".
The first adjoint call compiles the numba kernel (or loads it from its cache) before timing.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from contract.idm import I24_IDM
from sim.drives import load_drive
from sim.energy import RAV4_2019
from sim.gaps import GapBounds
from sim.optimum import (
    HUMANS,
    OptimumSettings,
    _platoon_cost_gradient,
    _sweep_inputs,
    optimal_trajectory,
)
from sim.platoon import platoon_roles, simulate_platoon

ROOT = Path(__file__).resolve().parents[1]
DRIVES = ROOT.parent / "shared/data/trajectories"
DEFAULT_DRIVES = (DRIVES / "2021-03-08-22-35-14_masterArray_0_5373.csv",)


def best_of(repeat: int, run: Callable[[], object]) -> tuple[float, float]:
    """Best wall and CPU seconds of `repeat` calls."""
    walls, cpus = [], []
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        run()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return min(walls), min(cpus)


def bench_drive(path: Path, repeat: int) -> None:
    """Print the figures of one drive."""
    drive = load_drive(path)
    baseline = simulate_platoon(drive, platoon_roles(HUMANS + 1, 0))
    fixed = _sweep_inputs(drive, baseline, GapBounds(), OptimumSettings(), I24_IDM, RAV4_2019)
    request = np.diff(baseline.speed_mps[:, 1]) / drive.dt_s
    gradient = np.zeros(drive.steps)
    _platoon_cost_gradient(request, *fixed, 1.0, gradient)  # compile or load the cache
    sweep = best_of(repeat, lambda: _platoon_cost_gradient(request, *fixed, 1.0, gradient))
    simulate = best_of(repeat, lambda: simulate_platoon(drive, platoon_roles(HUMANS + 1, 0)))
    wall, cpu = time.perf_counter(), time.process_time()
    result = optimal_trajectory(drive)
    bound = (time.perf_counter() - wall, time.process_time() - cpu)
    print(f"{drive.name}: {drive.steps} steps x {HUMANS + 1} followers")
    print(f"  baseline simulate_platoon: {simulate[0]:.3f} s wall, {simulate[1]:.3f} s CPU")
    print(
        f"  adjoint sweep (forward + backward): {sweep[0] * 1e3:.1f} ms wall, "
        f"{sweep[1] * 1e3:.1f} ms CPU ({simulate[1] / sweep[1]:.0f}x faster than simulating)"
    )
    print(
        f"  whole bound: {bound[0]:.1f} s wall, {bound[1]:.1f} s CPU, "
        f"{result.iterations} L-BFGS-B iterations, fuel saving {result.fuel_saving_pct:+.2f} %"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drive", type=Path, action="append", dest="drives")
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    for path in args.drives or DEFAULT_DRIVES:
        bench_drive(path, args.repeat)


if __name__ == "__main__":
    main()
