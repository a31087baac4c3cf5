"""Recorded CAN traffic in libpanda's CSV format (`Time,Bus,MessageID,Message,MessageLength`):
read it back as python-can frames, e.g. to replay a drive into the agent or to check decoding.

The payload column is hex without leading zeros (left-padded here to 2 x MessageLength digits).
Rows whose payload is not hex (spreadsheet tools turn some into numbers such as `5.90E+90`) are
counted and skipped, never guessed.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import can


@dataclass
class Recording:
    """The usable frames of a recording and how many rows were unusable."""

    frames: list[can.Message] = field(default_factory=list)
    malformed_rows: list[int] = field(default_factory=list)


def read_libpanda_csv(path: Path) -> Recording:
    """All frames of a libpanda CSV recording, in file order (row numbers: header = 1)."""
    recording = Recording()
    with path.open(newline="", encoding="utf-8") as handle:
        for number, row in enumerate(csv.DictReader(handle), start=2):
            try:
                length = int(row["MessageLength"])
                payload = bytes.fromhex(row["Message"].strip().zfill(2 * length))
                if len(payload) != length:
                    raise ValueError("payload longer than MessageLength")
                frame = can.Message(
                    timestamp=float(row["Time"]),
                    arbitration_id=int(row["MessageID"]),
                    data=payload,
                    channel=int(row["Bus"]),
                    is_extended_id=int(row["MessageID"]) > 0x7FF,
                )
            except (KeyError, TypeError, ValueError):
                recording.malformed_rows.append(number)
                continue
            recording.frames.append(frame)
    return recording
