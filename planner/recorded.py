"""Recorded drives with the INRIX minutes of the same time, as planner inputs.

Reads a folder of ../shared/data/trajectories_with_inrix with `contract.recorded`. Times are
returned relative to the drive's start, so the INRIX minutes and the drive share one clock.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from contract.corridor import CorridorGeometry
from contract.recorded import read_inrix_minutes, read_trajectory
from planner.evaluation import ProbeDrive
from planner.inputs import CorridorGrid, FloatArray, InrixHistory


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


@dataclass(frozen=True)
class CorridorFrame:
    """The corridor the recorded drives are read onto: its planner grid, its geometry, and the
    speed.csv column and centre of each of its INRIX segments (in the seed's order)."""

    grid: CorridorGrid
    geometry: CorridorGeometry
    inrix_columns: list[int]
    inrix_center_x_m: FloatArray

    @classmethod
    def of(cls, document: Mapping[str, Any]) -> CorridorFrame:
        """From a seed corridor document (`app.seed.seed_corridor_document()`): an INRIX
        segment's `xd_code` ends in its column of the recordings."""
        grid = CorridorGrid.from_rows(document["corridor"], document["i24_segments"])
        geometry = CorridorGeometry.from_segments(
            grid.corridor_id, grid.lanes, document["i24_segments"]
        )
        inrix = document["inrix_segments"]
        return cls(
            grid,
            geometry,
            [int(segment["xd_code"].rsplit("-", 1)[1]) for segment in inrix],
            np.array([(segment["start_x_m"] + segment["end_x_m"]) / 2 for segment in inrix]),
        )

    def load(self, folder: Path) -> RecordedProbe:
        """A folder of trajectories_with_inrix on this corridor (`load_recorded_drive`)."""
        return load_recorded_drive(folder, self.geometry, self.inrix_columns, self.inrix_center_x_m)
