"""Recorded drives with the INRIX minutes of the same time, as planner inputs.

Reads a folder of ../shared/data/trajectories_with_inrix with `contract.recorded`. Times are
returned relative to the drive's start, so the INRIX minutes and the drive share one clock.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from contract.corridor import CorridorGeometry
from contract.recorded import read_inrix_minutes, read_trajectory
from planner.evaluation import ProbeDrive
from planner.inputs import FloatArray, InrixHistory


@dataclass(frozen=True)
class RecordedProbe:
    """One folder: the probe's drive on the corridor and the INRIX history of its minutes."""

    name: str
    drive: ProbeDrive
    inrix: InrixHistory


def load_recorded_drive(
    folder: Path,
    geometry: CorridorGeometry,
    inrix_columns: Sequence[int],
    segment_center_x_m: FloatArray,
) -> RecordedProbe:
    """The drive's on-corridor samples and the INRIX speeds of the corridor's segments.

    `inrix_columns[j]` is the speed.csv column of the corridor's j-th INRIX segment, whose
    centre is `segment_center_x_m[j]`.
    """
    trajectory = read_trajectory(folder / "trajectory.csv")
    minutes = read_inrix_minutes(folder)
    time_s = trajectory.time_unix_s - trajectory.time_unix_s[0]
    located = geometry.locate(trajectory.latitude_deg, trajectory.longitude_deg)
    on = located.on_corridor & np.isfinite(trajectory.speed_mps)
    drive = ProbeDrive(time_s[on], located.x_m[on], trajectory.speed_mps[on])
    inrix = InrixHistory(
        measured_at_s=minutes.time_s,
        speed_mps=minutes.speed_mps[:, list(inrix_columns)],
        segment_center_x_m=np.asarray(segment_center_x_m, dtype=np.float64),
    )
    return RecordedProbe(folder.name, drive, inrix)
