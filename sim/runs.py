"""Every run's trajectories on disk, so a reviewer can recompute fuel, throughput and gaps.

`smoothfleet sim evaluate --save-runs DIR` writes one Parquet file per run (the baseline of
each drive included) at the simulator's own time step, long format, one row per vehicle and
step: `time_s, vehicle` (0 = the leader, then the platoon in order; cars that merged in from
the next lane after them, from the step they merged), `role` (leader | av | human),
`position_m, speed_mps, accel_mps2, length_m`; and `DIR/runs.csv` naming each file with its
`scenario, drive, planner, controller, avs`.
"""

from __future__ import annotations

import csv
import hashlib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from sim.platoon import PlatoonRun

if TYPE_CHECKING:
    import pandas as pd

RUNS_INDEX = "runs.csv"
INDEX_COLUMNS = ("file", "scenario", "drive", "planner", "controller", "avs")


def run_file_name(scenario: str, drive: str, planner: str, controller: str, avs: int) -> str:
    """A file name that is the same for the same run in every process."""
    key = "|".join([scenario, drive, planner, controller, str(avs)])
    digest = hashlib.sha1(key.encode()).hexdigest()[:12]
    return f"{scenario}_{drive[:19]}_{digest}.parquet"


def trajectory_table(run: PlatoonRun) -> pd.DataFrame:
    """The run in the long format of the module docstring (rows where a vehicle exists)."""
    import pandas as pd  # only `--save-runs` writes tables: every other command starts without

    position = run.position_m
    speed = run.speed_mps
    roles = np.where(run.is_av, "av", "human").astype(object)
    roles[0] = "leader"
    if run.cut_in_position_m is not None and run.cut_in_speed_mps is not None:
        position = np.hstack([position, run.cut_in_position_m])
        speed = np.hstack([speed, run.cut_in_speed_mps])
        roles = np.concatenate([roles, np.full(run.cut_ins, "human", dtype=object)])
    steps, vehicles = position.shape
    accel = np.vstack([np.diff(speed, axis=0) / run.dt_s, np.full((1, vehicles), np.nan)])
    table = pd.DataFrame(
        {
            "time_s": np.repeat(np.arange(steps) * run.dt_s, vehicles),
            "vehicle": np.tile(np.arange(vehicles), steps),
            "role": np.tile(roles, steps),
            "position_m": position.ravel(),
            "speed_mps": speed.ravel(),
            "accel_mps2": accel.ravel(),
            "length_m": run.vehicle_length_m,
        }
    )
    exists: pd.Series = table["position_m"].notna()
    return table[exists].reset_index(drop=True)


def write_run(directory: Path, name: str, run: PlatoonRun) -> None:
    """One run's trajectories as `directory/name` (Parquet)."""
    directory.mkdir(parents=True, exist_ok=True)
    trajectory_table(run).to_parquet(directory / name, index=False)


def write_runs_index(directory: Path, runs: Sequence[tuple[str, str, str, str, str, int]]) -> Path:
    """`runs.csv`: which file holds which run (file, scenario, drive, planner, controller, avs)."""
    path = directory / RUNS_INDEX
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(INDEX_COLUMNS)
        writer.writerows(runs)
    return path
