"""Real drives with the real INRIX minutes recorded beside them (../shared/data/
trajectories_with_inrix/): the planner in the loop reads what INRIX actually said.

The recorded segment positions are in the frame of the I-24 reference line; the simulator works
in distance along the drive. The drive's first GPS fix on the seed corridor (the same reference
line resampled), less the distance driven to it, gives the offset between the two. Each row of
speed.csv is the response received at that time (relative to the drive's start), so it reaches
the planner then: the feed's own ~3-minute lag is inside the numbers, as on the road.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from contract.corridor import CorridorGeometry
from contract.recorded import InrixMinutes, RecordingError, read_inrix_minutes, read_trajectory
from sim.drives import Drive, DriveError, replayable
from sim.traffic import InrixFeed

# A recording may begin before the GPS has a fix, or on the ramp: its first fix on the corridor
# places it if it comes within this much driving of the start (on every shared recording it is
# the very first fix, 5.6-14.5 m from the reference line). Further on, the distance driven
# would no longer say where on the corridor the drive began.
MAX_DRIVEN_TO_FIRST_FIX_M = 1000.0


@dataclass(frozen=True)
class RecordedDrive:
    """A real drive and the INRIX feed of the same minutes, in the drive's frame."""

    drive: Drive
    feed: InrixFeed


def seed_corridor() -> tuple[CorridorGeometry, float]:
    """The seed corridor's geometry and where its x_m = 0 lies on the reference line."""
    document = json.loads(resources.files("seed_data").joinpath("i24_wb_corridor.json").read_text())
    corridor = document["corridor"]
    geometry = CorridorGeometry.from_segments(
        corridor["corridor_id"], corridor["lanes"], document["i24_segments"]
    )
    return geometry, float(corridor["reference_line_origin_m"])


def feed_in_drive_frame(recording: InrixMinutes, start_reference_m: float) -> InrixFeed:
    """The recorded minutes as a feed whose positions count from the drive's start."""
    starts = recording.segment_start_m - start_reference_m
    last_length = float(np.median(np.diff(starts)))
    ends = np.append(starts[1:], starts[-1] + last_length)
    return InrixFeed(
        segment_start_m=starts,
        segment_end_m=ends,
        measured_at_s=recording.time_s,
        speed_mps=recording.speed_mps,
        latency_s=0.0,
    )


def load_recorded_drive(
    directory: Path, geometry: CorridorGeometry, origin_m: float
) -> RecordedDrive:
    """One folder of trajectories_with_inrix, its feed placed along the drive."""
    try:
        trajectory = read_trajectory(directory / "trajectory.csv")
        minutes = read_inrix_minutes(directory)
    except RecordingError as error:
        raise DriveError(str(error)) from None
    drive = replayable(trajectory)
    located = geometry.locate(trajectory.latitude_deg, trajectory.longitude_deg)
    on_corridor = np.flatnonzero(located.on_corridor)
    speed, time_s = trajectory.speed_mps, trajectory.time_unix_s
    driven_m = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(time_s))])
    if len(on_corridor) == 0 or driven_m[on_corridor[0]] > MAX_DRIVEN_TO_FIRST_FIX_M:
        raise DriveError(
            f"{directory.name}: no GPS fix on the seed corridor within the drive's first "
            f"{MAX_DRIVEN_TO_FIRST_FIX_M:g} m"
        )
    first = on_corridor[0]
    start_reference = float(located.x_m[first] - driven_m[first]) + origin_m
    return RecordedDrive(drive, feed_in_drive_frame(minutes, start_reference))


def load_recorded_drives(directory: Path) -> list[RecordedDrive]:
    """Every drive folder of trajectories_with_inrix, in name order."""
    folders = (
        sorted(path for path in directory.iterdir() if path.is_dir()) if directory.is_dir() else []
    )
    if not folders:
        raise DriveError(f"{directory}: no drive folders with INRIX recordings")
    geometry, origin = seed_corridor()
    return [load_recorded_drive(folder, geometry, origin) for folder in folders]
