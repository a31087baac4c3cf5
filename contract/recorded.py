"""Readers of the recorded CIRCLES data (../shared/data/README.md), one per file format.

- a drive CSV (`trajectories/*.csv`, `trajectories_with_inrix/*/trajectory.csv`): the
  instrumented RAV4 at 10 Hz, `Time` in unix seconds, `Velocity` in km/h, GPS position;
- the INRIX minutes beside a drive (`trajectories_with_inrix/*/`): `segments.json` (segment
  starts along the I-24 reference line, m) and `speed.csv` (m/s), `confidence.csv` (score),
  `cvalue.csv`, one row per minute, `time` relative to the drive's first sample.

The simulator, the planner's quality report and the INRIX converter all read through these, so a
file is parsed one way. Only numpy and the standard library: the car may use them too. An empty
cell is NaN (the consumer decides what a hole means); text that is not a number is an error
naming the file and row.
"""

from __future__ import annotations

import csv
import json
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from contract.units import MPS_PER_KPH

FloatArray = NDArray[np.float64]

DRIVE_COLUMNS = ("Time", "Velocity")
GPS_COLUMNS = ("LatitudeGPS", "LongitudeGPS")
INRIX_TABLES = ("speed.csv", "confidence.csv", "cvalue.csv")


class RecordingError(ValueError):
    """A recorded file that cannot be read; the message names the file, the row and the fault."""


@dataclass(frozen=True)
class RecordedTrajectory:
    """One drive CSV as recorded: times, speeds (converted to m/s) and GPS fixes (NaN if absent)."""

    path: Path
    time_unix_s: FloatArray
    speed_mps: FloatArray
    latitude_deg: FloatArray
    longitude_deg: FloatArray

    @property
    def name(self) -> str:
        """The drive's name: the file's stem, or its folder's for a `trajectory.csv`."""
        return self.path.parent.name if self.path.name == "trajectory.csv" else self.path.stem


@dataclass(frozen=True)
class InrixMinutes:
    """The INRIX readings recorded beside a drive: one row per minute, one column per segment.

    `segment_start_m` is in the frame of the I-24 reference line; `time_s` is relative to the
    drive's first sample (negative: minutes before the drive).
    """

    segment_start_m: FloatArray
    time_s: FloatArray
    speed_mps: FloatArray
    score: FloatArray
    c_value: FloatArray


def _header(path: Path) -> list[str]:
    """The first row's names. A UTF-8 byte-order mark (what a spreadsheet writes) is no part of
    the first name; text that is not UTF-8 is refused by the file's name."""
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            return [name.strip() for name in next(csv.reader(handle), [])]
    except OSError as error:
        raise RecordingError(f"{path}: {error.strerror}") from None
    except UnicodeDecodeError as error:
        raise RecordingError(_not_utf8(path, error)) from None


def _not_utf8(path: Path, error: UnicodeDecodeError) -> str:
    return f"{path}: not UTF-8 text ({error.reason}); save it as CSV UTF-8"


def _numbers(path: Path, indices: Sequence[int]) -> FloatArray:
    """The cells of the given columns as floats (rows after the header; empty -> NaN)."""
    try:
        # numpy's C parser reads a clean file in a third of the time; a file with holes or text
        # takes the cell-by-cell path below, which names the row.
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", "loadtxt: input contained no data")
            return np.loadtxt(
                path, delimiter=",", skiprows=1, usecols=list(indices), ndmin=2, dtype=np.float64
            )
    except ValueError:  # a decoding error among them: the path below names it
        pass
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            rows = list(csv.reader(handle))
    except UnicodeDecodeError as error:
        raise RecordingError(_not_utf8(path, error)) from None
    values = np.full((len(rows) - 1, len(indices)), np.nan)
    for number, row in enumerate(rows[1:], start=2):
        for column, index in enumerate(indices):
            cell = row[index].strip() if index < len(row) else ""
            if not cell:
                continue
            try:
                values[number - 2, column] = float(cell)
            except ValueError:
                raise RecordingError(f"{path} row {number}: {cell!r} is not a number") from None
    return values


def read_trajectory(path: Path) -> RecordedTrajectory:
    """A drive CSV."""
    if not path.is_file():
        raise RecordingError(f"{path}: no such drive file")
    header = _header(path)
    missing = [name for name in DRIVE_COLUMNS if name not in header]
    if missing:
        raise RecordingError(f"{path}: no column {', '.join(missing)}")
    names = [*DRIVE_COLUMNS, *(name for name in GPS_COLUMNS if name in header)]
    table = _numbers(path, [header.index(name) for name in names])
    columns = dict(zip(names, table.T, strict=True))
    absent = np.full(len(table), np.nan)
    return RecordedTrajectory(
        path=path,
        time_unix_s=columns["Time"],
        speed_mps=columns["Velocity"] * MPS_PER_KPH,
        latitude_deg=columns.get("LatitudeGPS", absent),
        longitude_deg=columns.get("LongitudeGPS", absent),
    )


def _minute_table(path: Path, segments: int) -> tuple[FloatArray, FloatArray]:
    """`time` and one column per segment, headed 0, 1, ... in order."""
    header = _header(path)
    expected = ["time", *(str(column) for column in range(segments))]
    if header != expected:
        raise RecordingError(
            f"{path}: header {','.join(header)!r}, expected time and the {segments} segment "
            "columns of segments.json"
        )
    table = _numbers(path, range(len(header)))
    return table[:, 0], table[:, 1:]


def read_inrix_minutes(folder: Path) -> InrixMinutes:
    """The feed files of one trajectories_with_inrix folder."""
    try:
        starts = np.asarray(json.loads((folder / "segments.json").read_text()), dtype=np.float64)
    except (OSError, ValueError, TypeError) as error:
        raise RecordingError(f"{folder / 'segments.json'}: {error}") from None
    if starts.ndim != 1 or len(starts) == 0:
        raise RecordingError(f"{folder / 'segments.json'}: not a list of segment starts")
    tables = [_minute_table(folder / name, len(starts)) for name in INRIX_TABLES]
    (time_s, speed), (score_time, score), (c_time, c_value) = tables
    if not (np.array_equal(time_s, score_time) and np.array_equal(time_s, c_time)):
        raise RecordingError(f"{folder.name}: speed, confidence and cvalue rows differ")
    # A feed's minutes come one after another: a repeated or reversed minute was refused only
    # once simulating had begun, by the planner, without naming the folder.
    backwards = np.flatnonzero(~(np.diff(time_s) > 0))
    if backwards.size:
        row = int(backwards[0]) + 3  # the header is row 1
        raise RecordingError(
            f"{folder / 'speed.csv'} row {row}: time {time_s[row - 2]:g} s after "
            f"{time_s[row - 3]:g} s; the minutes must increase"
        )
    return InrixMinutes(
        segment_start_m=starts, time_s=time_s, speed_mps=speed, score=score, c_value=c_value
    )
