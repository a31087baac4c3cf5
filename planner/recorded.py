"""Recorded drives with the INRIX minutes of the same time, as planner inputs.

Reads a folder of ../shared/data/trajectories_with_inrix: `trajectory.csv` (10 Hz; Time in
unix seconds, Velocity in km/h, GPS latitude/longitude) and `speed.csv` (one row per minute:
seconds relative to the drive's start, then one speed in m/s per INRIX column). Times are
returned relative to the drive's start, so the INRIX minutes and the drive share one clock.
"""

from __future__ import annotations

import csv
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from contract.corridor import CorridorGeometry
from planner.evaluation import Drive
from planner.inputs import FloatArray, InrixHistory

KMH = 1 / 3.6  # m/s per km/h


@dataclass(frozen=True)
class RecordedDrive:
    """One folder: the probe's drive on the corridor and the INRIX history of its minutes."""

    name: str
    drive: Drive
    inrix: InrixHistory


def _columns(path: Path, names: Sequence[str]) -> dict[str, FloatArray]:
    """The named numeric columns of a CSV file (an empty cell is NaN)."""
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    header = [name.strip() for name in rows[0]]
    missing = [name for name in names if name not in header]
    if missing:
        raise ValueError(f"{path}: no column {', '.join(missing)}")
    columns = {}
    for name in names:
        index = header.index(name)
        columns[name] = np.array(
            [float(row[index]) if row[index].strip() else np.nan for row in rows[1:]]
        )
    return columns


def load_recorded_drive(
    folder: Path,
    geometry: CorridorGeometry,
    inrix_columns: Sequence[int],
    segment_center_x_m: FloatArray,
) -> RecordedDrive:
    """The drive's on-corridor samples and the INRIX speeds of the corridor's segments.

    `inrix_columns[j]` is the speed.csv column of the corridor's j-th INRIX segment, whose
    centre is `segment_center_x_m[j]`.
    """
    trajectory = _columns(
        folder / "trajectory.csv", ("Time", "Velocity", "LatitudeGPS", "LongitudeGPS")
    )
    time_s = trajectory["Time"] - trajectory["Time"][0]
    located = geometry.locate(trajectory["LatitudeGPS"], trajectory["LongitudeGPS"])
    on = located.on_corridor & np.isfinite(trajectory["Velocity"])
    drive = Drive(time_s[on], located.x_m[on], trajectory["Velocity"][on] * KMH)
    speeds = _columns(folder / "speed.csv", ["time", *(str(column) for column in inrix_columns)])
    inrix = InrixHistory(
        measured_at_s=speeds["time"],
        speed_mps=np.column_stack([speeds[str(column)] for column in inrix_columns]),
        segment_center_x_m=np.asarray(segment_center_x_m, dtype=np.float64),
    )
    return RecordedDrive(folder.name, drive, inrix)
