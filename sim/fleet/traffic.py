"""The demo's road: real stop-and-go traffic laid over the seed corridor, as INRIX reports it and
as the fleet's cars meet it.

The traffic is the wave field of a real I-24 drive (`sim.traffic.WaveField`), replayed in
a loop so waves keep travelling upstream through the corridor for as long as the demo runs. From
it come:
- the simulated INRIX feed: per seed segment, the mean speed over the minute that ended 180 s
  ago (paper Table 1), as a provider-format response for POST /api/v1/feeds/inrix;
- the human drivers ahead of the fleet's cars: each drives at the traffic's speed where it is,
  all advanced together (vectorised) once per demo step.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contract.units import MPS_PER_MPH
from sim.drives import Drive, drive_from_speeds
from sim.traffic import INRIX_LATENCY_S, INRIX_PERIOD_S, SAMPLE_SPACING_M, WaveField

FloatArray = NDArray[np.float64]

# The field is looped this long before it wraps around (a long demo sees one jump per period).
LOOP_HOURS = 6.0
# Samples per minute when averaging a segment's speed (every 5 s).
SAMPLE_PERIOD_S = 5.0
# INRIX confidence score for real-time readings (the paper's data: 30 real-time).
REAL_TIME_SCORE = 30


def synthetic_waves(duration_s: float = 1200.0) -> Drive:
    """Stop-and-go without the shared data: speed swinging 5-25 m/s every 4 minutes."""
    time_s = np.arange(0.0, duration_s, 0.1)
    return drive_from_speeds("synthetic waves", 15.0 + 10.0 * np.sin(2 * np.pi * time_s / 240.0))


@dataclass(frozen=True)
class Segment:
    """A seed INRIX segment: its code and where it lies on the corridor."""

    code: str
    start_x_m: float
    end_x_m: float


class CorridorTraffic:
    """The looped wave field of a real drive along the corridor; time is seconds of demo."""

    def __init__(self, drive: Drive, *, start_offset_s: float = 0.0) -> None:
        laps = int(np.ceil(LOOP_HOURS * 3600.0 / drive.duration_s))
        self.looped = drive_from_speeds(
            f"{drive.name} x{laps}", np.tile(drive.speed_mps[:-1], laps), drive.dt_s
        )
        self.field = WaveField(self.looped)
        self.period_s = self.looped.duration_s
        self.start_offset_s = start_offset_s
        self.source = drive.name

    def speed_mps(self, time_s: float | FloatArray, x_m: FloatArray) -> FloatArray:
        """Traffic speed at demo time(s) `time_s` and corridor positions `x_m`."""
        field_time = (np.asarray(time_s) + self.start_offset_s) % self.period_s
        return self.field.speed_mps(field_time, x_m)

    def segment_speeds_mps(self, minute_end_s: float, segments: Sequence[Segment]) -> FloatArray:
        """Mean speed of each segment over the minute ending at `minute_end_s`."""
        offsets = np.arange(int(INRIX_PERIOD_S / SAMPLE_PERIOD_S), dtype=np.float64) + 0.5
        times: FloatArray = minute_end_s - INRIX_PERIOD_S + SAMPLE_PERIOD_S * offsets
        means = np.empty(len(segments))
        for index, segment in enumerate(segments):
            count = max(1, int(round((segment.end_x_m - segment.start_x_m) / SAMPLE_SPACING_M)))
            step = (segment.end_x_m - segment.start_x_m) / count
            xs: FloatArray = segment.start_x_m + (np.arange(count, dtype=np.float64) + 0.5) * step
            means[index] = float(self.speed_mps(times[:, None], xs[None, :]).mean())
        return means

    def inrix_response(
        self, demo_time_s: float, wall_time: datetime, segments: Sequence[Segment]
    ) -> dict[str, Any]:
        """What INRIX answers at `demo_time_s`: the minute that ended `INRIX_LATENCY_S` ago,
        stamped with that minute's end, in the provider's format (mph)."""
        minute_end = demo_time_s - INRIX_LATENCY_S
        stamp = (wall_time - timedelta(seconds=INRIX_LATENCY_S)).isoformat()
        speeds = self.segment_speeds_mps(minute_end, segments)
        readings = []
        for segment, speed in zip(segments, speeds, strict=True):
            length = segment.end_x_m - segment.start_x_m
            readings.append(
                {
                    "code": segment.code,
                    "type": "XDS",
                    "speed": round(float(speed) / MPS_PER_MPH, 2),
                    "score": REAL_TIME_SCORE,
                    "c-Value": 100.0,
                    "segmentClosed": False,
                    "travelTimeMinutes": round(length / max(float(speed), 0.1) / 60.0, 4),
                }
            )
        return {
            "docType": "GetSegmentSpeed",
            "statusId": 0,
            "statusText": "OK",
            "createdDate": stamp,
            "result": {"segmentspeeds": [{"timestamp": stamp, "segments": readings}]},
        }


class TrafficLeaders:
    """The human cars just ahead of each fleet car, driving at the traffic's speed.

    Positions are along the corridor; `wrap(i, length)` moves a leader back by a lap when its
    follower leaves the corridor and re-enters at the start.
    """

    def __init__(self, traffic: CorridorTraffic, positions_m: FloatArray, start_s: float) -> None:
        self.traffic = traffic
        self.position_m = np.asarray(positions_m, dtype=np.float64).copy()
        self.speed_mps = traffic.speed_mps(start_s, self.position_m)
        self.time_s = start_s

    def advance(self, time_s: float) -> None:
        """Move every leader to `time_s` (steps of at most 0.1 s)."""
        while self.time_s < time_s - 1e-9:
            dt = min(0.1, time_s - self.time_s)
            self.position_m += self.speed_mps * dt
            self.time_s += dt
            self.speed_mps = self.traffic.speed_mps(self.time_s, self.position_m)

    def wrap(self, index: int, lap_m: float) -> None:
        """Move leader `index` back by one lap (its follower re-entered the corridor)."""
        self.position_m[index] -= lap_m

    def leader(self, index: int) -> FleetLeader:
        """The `Leader` (sim.emulator.leaders protocol) of fleet car `index`."""
        return FleetLeader(self, index)


@dataclass(frozen=True)
class FleetLeader:
    """One car's leader, read from the shared vectorised state."""

    leaders: TrafficLeaders
    index: int

    def state(self, time_s: float) -> tuple[float, float]:
        """(rear bumper position, speed) now; the leaders are advanced by the demo loop."""
        return float(self.leaders.position_m[self.index]), float(self.leaders.speed_mps[self.index])
