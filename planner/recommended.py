"""The planner the fleet runs: one definition for the server's schedule and the simulator.

`smoothfleet sim select` (leave-one-date-out cross-validation on the shared drives;
docs/simulation.md reports the held-out folds only) chose the window; the allowance over the
posted limit is the paper's (its fleet drove up to 73 mph on the 70 mph road, its ACC clip), and
without it a fleet follows traffic flowing at 72 mph at 70 and falls back from it. The
algorithm is the issue's pair, kernel smoothing (the paper's steps 1-3): on the 32 shared
drives the simulator cannot tell it from `kernel_smooth_buffer`, whose buffer acts only upstream
of a standing bottleneck, which none of them holds (docs/planner.md). The server plans with
these unless `SMOOTHFLEET_PLANNER_ALGORITHM` / `SMOOTHFLEET_PLANNER_PARAMS` say otherwise, so
what the simulator evaluates is what the cars follow.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

RECOMMENDED_PLANNER = "kernel_smooth"
# Typed read-only, so every caller starts from the same figures; a plain dict, because the
# simulator pickles it to its worker processes.
RECOMMENDED_PLANNER_PARAMS: Mapping[str, Any] = {
    "window_m": 4000,
    "speed_limit_allowance_mps": 1.34112,  # 3 mph
}
