"""Recorded INRIX snapshots: a JSON Lines file, and a converter from the shared drive data.

Format (one line per snapshot, in the order they were received):

    {"recorded_at": "2021-03-15T13:17:50.700Z", "response": { ...provider response... }}

`recorded_at` is when the response arrived from the provider; `response` is the body exactly as
the provider sent it (mph). `smoothfleet inrix poll --record FILE` writes this format and
`smoothfleet inrix replay FILE` reads it. `smoothfleet inrix convert DRIVE_DIR FILE` makes one
from a folder of ../shared/data/trajectories_with_inrix/ (per-minute segment speeds in m/s,
INRIX score and c-Value per segment): each minute becomes a provider-format response whose
segment codes are SF-I24WB-NN, NN being the column of those files (seed_data/build.py).
"""

from __future__ import annotations

import contextlib
import errno
import math
from collections.abc import Iterable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import orjson

from app.feeds.inrix import S_PER_MINUTE
from contract.recorded import RecordingError, read_inrix_minutes, read_trajectory
from contract.units import MPS_PER_MPH


@dataclass(frozen=True)
class RecordedSnapshot:
    """A provider response and when it was received."""

    recorded_at: datetime
    response: dict[str, Any]
    # Its line in the recording it was read from (None: fetched live), to name it in an error.
    line: int | None = None


def to_line(snapshot: RecordedSnapshot) -> bytes:
    """One line of a recording (with its newline)."""
    return orjson.dumps(
        {"recorded_at": snapshot.recorded_at, "response": snapshot.response},
        option=orjson.OPT_UTC_Z | orjson.OPT_APPEND_NEWLINE,
    )


def write_recording(path: Path, snapshots: Iterable[RecordedSnapshot]) -> int:
    """Write the snapshots to a new recording; returns how many."""
    count = 0
    with path.open("wb") as handle:
        for snapshot in snapshots:
            handle.write(to_line(snapshot))
            count += 1
    return count


def append_to_recording(path: Path, snapshot: RecordedSnapshot) -> None:
    """Append one snapshot. A write that fails (a full disk) is undone back to the last whole
    line before the error is raised: a line cut short would make `read_recording` refuse the
    whole file."""
    line = memoryview(to_line(snapshot))
    with path.open("ab", buffering=0) as handle:  # unbuffered: every byte written is known
        whole_until = handle.tell()
        try:
            while line:
                written = handle.write(line)
                if not written:  # a regular file takes a byte or raises; never spin on one
                    raise OSError(errno.EIO, f"{path}: nothing written")
                line = line[written:]
        except OSError:
            # the write's error is the one to raise, even when nothing can be undone (a device
            # such as /dev/full cannot be truncated)
            with contextlib.suppress(OSError):
                handle.truncate(whole_until)
            raise


def read_recording(path: Path) -> list[RecordedSnapshot]:
    """The snapshots of a recording in the order they were received."""
    try:
        lines = path.read_bytes().splitlines()
    except OSError as error:
        raise RecordingError(f"{path}: {error.strerror}") from None
    snapshots = []
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            entry = orjson.loads(line)
            recorded_at = datetime.fromisoformat(entry["recorded_at"])
            response = entry["response"]
        except (orjson.JSONDecodeError, KeyError, TypeError, ValueError) as error:
            raise RecordingError(
                f"{path.name} line {number}: not a recorded snapshot "
                f'({{"recorded_at": ..., "response": {{...}}}}): {error}'
            ) from None
        if recorded_at.tzinfo is None or not isinstance(response, dict):
            raise RecordingError(
                f"{path.name} line {number}: recorded_at needs a zone and response an object"
            )
        snapshots.append(RecordedSnapshot(recorded_at, response, number))
    # Stable: snapshots received at the same instant keep their order in the file.
    return sorted(snapshots, key=lambda snapshot: snapshot.recorded_at)


def segment_code(column: int) -> str:
    """Our segment code for a column of the recorded feed files (as seed_data/build.py)."""
    return f"SF-I24WB-{column:02d}"


def _iso(moment: float) -> str:
    return (
        datetime.fromtimestamp(moment, UTC)
        .isoformat(timespec="milliseconds")
        .replace("+00:00", "Z")
    )


def snapshots_from_drive(directory: Path) -> list[RecordedSnapshot]:
    """The per-minute INRIX readings of a recorded drive as provider-format snapshots."""
    start = float(read_trajectory(directory / "trajectory.csv").time_unix_s[0])
    minutes = read_inrix_minutes(directory)
    starts = minutes.segment_start_m.tolist()
    snapshots = []
    rows = zip(
        minutes.time_s.tolist(),
        minutes.speed_mps.tolist(),
        minutes.score.tolist(),
        minutes.c_value.tolist(),
        strict=True,
    )
    for relative, speed_row, score_row, c_row in rows:
        measured = _iso(start + relative)
        segments = []
        for column, speed_mps in enumerate(speed_row):
            if not math.isfinite(speed_mps):
                continue  # a minute the feed gave no speed for this segment: no reading
            segment: dict[str, Any] = {
                "code": segment_code(column),
                "type": "XDS",
                "speed": round(speed_mps / MPS_PER_MPH, 3),
                "segmentClosed": False,
            }
            # an empty score or c-Value cell is left out, as a provider leaves out what it lacks
            if math.isfinite(score_row[column]):
                segment["score"] = int(score_row[column])
            if math.isfinite(c_row[column]):
                segment["c-Value"] = c_row[column]
            # The last column's end is not in segments.json, so its length is unknown.
            if column + 1 < len(starts) and speed_mps > 0:
                length_m = starts[column + 1] - starts[column]
                segment["travelTimeMinutes"] = round(length_m / speed_mps / S_PER_MINUTE, 4)
            segments.append(segment)
        response = {
            "docType": "GetSegmentSpeed",
            "statusId": 0,
            "statusText": "OK",
            "createdDate": measured,
            "result": {"segmentspeeds": [{"timestamp": measured, "segments": segments}]},
        }
        snapshots.append(RecordedSnapshot(datetime.fromisoformat(measured), response))
    return snapshots
