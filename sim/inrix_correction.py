"""Would a fixed linear recalibration of INRIX bring the planner's input nearer the traffic?

    .venv/bin/python -m sim.inrix_correction [--data DIR]

The plans read slower than the traffic on the open road (the real feed's bias at or above
25 m/s is about -2.6 m/s against the probe car: docs/simulation.md, "Simulated INRIX"), and
every ACC-button controller that follows them falls back. The simplest correction a planner
could apply is a fixed map of each reading, probe ~ a + b x INRIX, fitted on past drives. This
measures it the way the planner would meet it: the car of every drive of
`trajectories_with_inrix` paired once a second with the reading it would hold (`ProbePairing`,
as stamped), the map fitted by least squares on the other dates only (two drives of one date saw
the same traffic), and scored on the held-out date: MAE, bias, and bias while the car is at or
above `FREEFLOW_FROM_MPS`, before and after.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.folds import drive_date
from sim.inrix import FREEFLOW_FROM_MPS, FloatArray, ProbePairing
from sim.recorded import load_recorded_drives

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "trajectories_with_inrix"


@dataclass(frozen=True)
class PairedReadings:
    """One drive's probe speeds and the INRIX readings held at the same seconds."""

    date: str
    inrix_mps: FloatArray
    probe_mps: FloatArray


@dataclass(frozen=True)
class HeldOutCorrection:
    """The map fitted without `date`, and the date's errors (reading - probe) before and after."""

    date: str
    seconds: int
    offset_mps: float
    gain: float
    mae_before_mps: float
    mae_after_mps: float
    bias_before_mps: float
    bias_after_mps: float
    open_road_bias_before_mps: float
    open_road_bias_after_mps: float


def held_out_corrections(drives: Sequence[PairedReadings]) -> list[HeldOutCorrection]:
    """For each date: probe = a + b x INRIX fitted on the other dates, scored on this one."""
    dates = sorted({drive.date for drive in drives})
    if len(dates) < 2:
        raise ValueError("leaving a date out needs drives of at least two dates")
    rows = []
    for date in dates:
        fitted = [drive for drive in drives if drive.date != date]
        gain, offset = np.polyfit(
            np.concatenate([drive.inrix_mps for drive in fitted]),
            np.concatenate([drive.probe_mps for drive in fitted]),
            1,
        )
        held = [drive for drive in drives if drive.date == date]
        inrix = np.concatenate([drive.inrix_mps for drive in held])
        probe = np.concatenate([drive.probe_mps for drive in held])
        before = inrix - probe
        after = offset + gain * inrix - probe
        open_road = probe >= FREEFLOW_FROM_MPS
        rows.append(
            HeldOutCorrection(
                date=date,
                seconds=int(probe.size),
                offset_mps=float(offset),
                gain=float(gain),
                mae_before_mps=float(np.mean(np.abs(before))),
                mae_after_mps=float(np.mean(np.abs(after))),
                bias_before_mps=float(np.mean(before)),
                bias_after_mps=float(np.mean(after)),
                open_road_bias_before_mps=_mean_where(before, open_road),
                open_road_bias_after_mps=_mean_where(after, open_road),
            )
        )
    return rows


def _mean_where(values: FloatArray, chosen: NDArray[np.bool_]) -> float:
    return float(np.mean(values[chosen])) if np.any(chosen) else float("nan")


def paired_readings(data: Path) -> list[PairedReadings]:
    """Every recorded drive's car against its real feed, as stamped (no shift)."""
    paired = []
    for recorded in load_recorded_drives(data):
        pairing = ProbePairing.along(recorded.drive, recorded.feed, np.array([0.0]))
        reading = recorded.feed.speed_mps.ravel()[pairing.flat_index[0]]
        usable = pairing.valid[0] & np.isfinite(reading)
        paired.append(
            PairedReadings(drive_date(recorded.drive), reading[usable], pairing.speed_mps[usable])
        )
    return paired


def main(argv: Sequence[str] | None = None) -> None:
    """Print one line per held-out date and the pooled MAE before and after."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA, help="trajectories_with_inrix")
    args = parser.parse_args(argv)
    rows = held_out_corrections(paired_readings(args.data))
    say = print  # noqa: T201 (a command-line report)
    say(
        "held-out date   seconds  fitted on the other dates   MAE m/s       bias m/s"
        "      open-road bias m/s   (before -> after)"
    )
    for row in rows:
        say(
            f"{row.date}   {row.seconds:6d}  probe = {row.offset_mps:5.2f} + {row.gain:.3f} x INRIX"
            f"   {row.mae_before_mps:5.2f} -> {row.mae_after_mps:5.2f}"
            f"   {row.bias_before_mps:+5.2f} -> {row.bias_after_mps:+5.2f}"
            f"   {row.open_road_bias_before_mps:+6.2f} -> {row.open_road_bias_after_mps:+6.2f}"
        )
    seconds = np.array([row.seconds for row in rows])
    before = np.array([row.mae_before_mps for row in rows])
    after = np.array([row.mae_after_mps for row in rows])
    say(
        f"every date held out once: MAE {np.average(before, weights=seconds):.2f} -> "
        f"{np.average(after, weights=seconds):.2f} m/s; better on "
        f"{int(np.sum(after < before))} of {len(rows)} dates"
    )


if __name__ == "__main__":
    main()
