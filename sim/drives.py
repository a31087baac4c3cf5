"""Real I-24 drives (10 Hz) that lead the simulated platoons, read with `contract.recorded` and
checked here for what a replay needs (no long gaps, finite non-negative speeds).

The data (../shared/data/README.md) is the CIRCLES instrumented RAV4 on I-24 near Nashville:
`Time` in unix seconds at 0.1 s steps, `Velocity` in km/h. A drive is replayed from its speed
alone: positions are the trapezoidal integral of the speed, so the leader's position, speed and
acceleration are consistent with each other (GPS distance is noisier than the wheel speed).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from contract.recorded import RecordedTrajectory, RecordingError, read_trajectory

FloatArray = NDArray[np.float64]

DriveKind = Literal["shockwave", "freeflow"]

# The recorder logs at 10 Hz; a step further than this from 0.1 s is off the grid.
STEP_S = 0.1
STEP_TOLERANCE_S = 0.011
# A recording may drop a few samples or log them off the 0.1 s grid: such a stretch, up to this
# long between two samples, is filled by linear interpolation onto the grid (as the shared
# dataset's own preparation filled its missing steps). A longer hole is refused: the leader's
# speed in it is unknown, and an interpolated wave is no wave the road made.
MAX_FILLED_GAP_S = 1.0
# A drive is free flow when even its slowest moments stay fast: its 2nd speed percentile at or
# above 20 m/s (72 km/h, 45 mph). Every drive below that has at least one real slowdown wave.
FREEFLOW_MIN_SPEED_MPS = 20.0
FREEFLOW_PERCENTILE = 2.0
# No car changes its speed faster than about 1 g: a step of the recording that does (a sample
# of 0 in the middle of a highway drive) is a sensor's glitch, which a replay would hand to
# the platoon as a braking no road made. The 32 shared drives stay under 6 m/s^2.
MAX_LEADER_ACCEL_MPS2 = 9.81


class DriveError(ValueError):
    """A drive file that cannot be replayed; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Drive:
    """One real drive: the leader's speed every `dt_s` seconds from `start_unix_s`."""

    name: str
    dt_s: float
    start_unix_s: float
    speed_mps: FloatArray
    # Seconds of the recording between samples more than a grid step apart, which the loader
    # filled by interpolation (0 for a drive logged on its grid).
    filled_s: float = 0.0

    @property
    def steps(self) -> int:
        """Number of time steps after the first sample."""
        return len(self.speed_mps) - 1

    @property
    def duration_s(self) -> float:
        """Length of the drive in seconds."""
        return self.steps * self.dt_s

    @property
    def position_m(self) -> FloatArray:
        """Distance driven since the first sample (trapezoidal integral of the speed)."""
        increments = 0.5 * (self.speed_mps[1:] + self.speed_mps[:-1]) * self.dt_s
        return np.concatenate([[0.0], np.cumsum(increments)])

    @property
    def accel_mps2(self) -> FloatArray:
        """Acceleration over each step (forward difference; the last step repeats)."""
        diff = np.diff(self.speed_mps) / self.dt_s
        return np.concatenate([diff, diff[-1:]])

    @property
    def glitches(self) -> tuple[int, float]:
        """How many steps change the speed faster than MAX_LEADER_ACCEL_MPS2, and the time
        (s from the start) of the first; (0, nan) when none does. They are replayed as
        recorded, and the commands that read drives say so."""
        fast = np.flatnonzero(np.abs(np.diff(self.speed_mps)) > MAX_LEADER_ACCEL_MPS2 * self.dt_s)
        return (len(fast), float(fast[0]) * self.dt_s) if len(fast) else (0, float("nan"))

    @property
    def fingerprint(self) -> str:
        """sha256 of the replayed speeds and their step, the first 16 hex digits: what a result
        computed on this drive (its optimal bound) was computed from. Two cuts or versions of a
        drive under one name differ here."""
        digest = hashlib.sha256(np.ascontiguousarray(self.speed_mps, dtype=np.float64).tobytes())
        digest.update(repr(self.dt_s).encode())
        return digest.hexdigest()[:16]

    @property
    def kind(self) -> DriveKind:
        """`freeflow` when the drive never slows into a wave, else `shockwave`."""
        slow = float(np.percentile(self.speed_mps, FREEFLOW_PERCENTILE))
        return "freeflow" if slow >= FREEFLOW_MIN_SPEED_MPS else "shockwave"

    def slice(self, start_s: float, duration_s: float) -> Drive:
        """A part of the drive (for short tests); the name says which part."""
        first = int(round(start_s / self.dt_s))
        last = first + int(round(duration_s / self.dt_s))
        if first < 0 or last > self.steps or last <= first:
            raise DriveError(
                f"{self.name}: slice {start_s}+{duration_s} s is outside the drive "
                f"(0-{self.duration_s:.1f} s)"
            )
        return Drive(
            name=f"{self.name}[{start_s:g}s+{duration_s:g}s]",
            dt_s=self.dt_s,
            start_unix_s=self.start_unix_s + first * self.dt_s,
            speed_mps=self.speed_mps[first : last + 1].copy(),
        )


def drive_from_speeds(name: str, speed_mps: FloatArray, dt_s: float = STEP_S) -> Drive:
    """A synthetic drive (e.g. a constant-speed leader) from a speed series."""
    speeds = np.asarray(speed_mps, dtype=np.float64)
    if speeds.ndim != 1 or len(speeds) < 2:
        raise DriveError(f"{name}: a drive needs at least two speed samples")
    if not np.all(np.isfinite(speeds)) or np.any(speeds < 0):
        raise DriveError(f"{name}: speeds must be finite and not negative")
    return Drive(name=name, dt_s=dt_s, start_unix_s=0.0, speed_mps=speeds)


def load_drive(path: Path) -> Drive:
    """Read a drive CSV (`Time` in unix s, `Velocity` in km/h) and check it can be replayed."""
    try:
        return replayable(read_trajectory(path))
    except RecordingError as error:
        raise DriveError(str(error)) from None


def replayable(recorded: RecordedTrajectory) -> Drive:
    """The recorded drive as a leader to replay, refused if it has holes or gaps."""
    path = recorded.path
    time_s, speed_mps = recorded.time_unix_s, recorded.speed_mps
    if len(time_s) < 2:
        raise DriveError(f"{path}: fewer than two samples")
    bad = ~np.isfinite(time_s) | ~np.isfinite(speed_mps) | (speed_mps < 0)
    if np.any(bad):
        row = int(np.argmax(bad)) + 2  # 1-based, after the header line
        raise DriveError(f"{path} row {row}: Time and Velocity must be finite, speed >= 0")
    steps = np.diff(time_s)
    for refused, reason in (
        (steps <= 0.0, "time does not increase (a repeated or out-of-order sample)"),
        (
            steps > MAX_FILLED_GAP_S + STEP_TOLERANCE_S,
            f"a gap in the recording, longer than the {MAX_FILLED_GAP_S:g} s the loader fills",
        ),
    ):
        if np.any(refused):
            first = int(np.argmax(refused))
            raise DriveError(f"{path} row {first + 3}: time step {steps[first]:.3f} s, {reason}")
    off_grid = np.abs(steps - STEP_S) > STEP_TOLERANCE_S
    if not np.any(off_grid):
        return Drive(
            name=recorded.name, dt_s=STEP_S, start_unix_s=float(time_s[0]), speed_mps=speed_mps
        )
    elapsed_s = time_s - time_s[0]
    grid_s = STEP_S * np.arange(int(np.floor(elapsed_s[-1] / STEP_S + 1e-6)) + 1)
    return Drive(
        name=recorded.name,
        dt_s=STEP_S,
        start_unix_s=float(time_s[0]),
        speed_mps=np.interp(grid_s, elapsed_s, speed_mps),
        filled_s=float(np.sum(steps[off_grid])),
    )


def load_drives(directory: Path) -> list[Drive]:
    """Every drive CSV of a directory, in name order.

    Every file is read before any is refused, so one error names every file that cannot be
    replayed (one line each): a folder of new drives is mended in one pass, not one run per
    bad file.
    """
    files = sorted(directory.glob("*.csv"))
    if not files:
        raise DriveError(f"{directory}: no drive CSV files")
    drives: list[Drive] = []
    refused: list[str] = []
    for path in files:
        try:
            drives.append(load_drive(path))
        except DriveError as error:
            refused.append(str(error))
    if len(refused) == 1:
        raise DriveError(refused[0])
    if refused:
        raise DriveError(
            f"{len(refused)} of the {len(files)} drives in {directory} cannot be replayed:\n"
            + "\n".join(refused)
        )
    return drives


# Where the shared data may be named explicitly (e.g. an installed copy of smoothfleet).
SHARED_DATA_ENV = "SMOOTHFLEET_SHARED_DATA"


def shared_data_dir(start: Path | None = None) -> Path:
    """The shared data folder: $SMOOTHFLEET_SHARED_DATA, else the `shared/data` beside the
    checkout this code (or the working directory) lies in, wherever it was cloned.

    Searched upward from the working directory and from this file: the first ancestor holding
    `shared/data/trajectories` wins. Raises DriveError naming what was searched.
    """
    explicit = os.environ.get(SHARED_DATA_ENV)
    if explicit:
        return Path(explicit)
    origins = [start or Path.cwd(), Path(__file__).resolve()]
    for origin in origins:
        for folder in [origin, *origin.parents]:
            candidate = folder / "shared" / "data"
            if (candidate / "trajectories").is_dir():
                return candidate
    raise DriveError(
        f"no shared/data/trajectories above {origins[0]} or {origins[1].parent}: "
        f"set {SHARED_DATA_ENV} or pass the folders explicitly"
    )
