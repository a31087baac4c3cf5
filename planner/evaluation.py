"""Quality of the TSE against a probe vehicle's real drive (the docs/planner.md report).

At every decision time t of a drive the planner sees the INRIX snapshots measured at least
`latency_s` before t (paper Table 1: ~180 s) and, for fusion, the probe's own pings of the
window before t. Its TSE is read along the path the probe then drives in [t, t + horizon) and
compared with the probe's mean speed over that minute. The variants:

- `inrix`: the newest visible snapshot, resampled (no prediction, no fusion);
- `predicted`: the configured predictor (default `wave_trend`) on the visible history;
- `fused`: the prediction fused with the probe's own earlier pings (1 Hz);
- `inrix_without_latency`: the snapshot of minute t itself, as if INRIX had no delay
  (a reference for what prediction could at best recover, not something a planner can see).

A decision time at which the planner has no usable INRIX reading (the feed had not reported
within its history window: some recordings hold one reading every 5 minutes) publishes no plan
on the server, so it is not scored; `DriveErrors.no_estimate_times_s` lists those times.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from planner.inputs import CorridorGrid, FloatArray, InrixHistory, LaneObservations
from planner.params import PlannerParams
from planner.pipeline import PlannerInputs, enhance_tse
from planner.predict import NoInrixEstimate

VARIANTS = ("inrix", "predicted", "fused", "inrix_without_latency")


@dataclass(frozen=True)
class ProbeDrive:
    """A probe vehicle's samples on the corridor: time (s), position x_m and speed (m/s)."""

    time_s: FloatArray
    x_m: FloatArray
    speed_mps: FloatArray

    def __post_init__(self) -> None:
        for name in ("time_s", "x_m", "speed_mps"):
            object.__setattr__(self, name, np.asarray(getattr(self, name), dtype=np.float64))
        if not len(self.time_s) == len(self.x_m) == len(self.speed_mps) > 1:
            raise ValueError("a drive needs equally long time, position and speed arrays")
        if np.any(np.diff(self.time_s) <= 0):
            raise ValueError("drive times must increase strictly")


@dataclass(frozen=True)
class DriveErrors:
    """Absolute errors (m/s) of each variant at each decision time of one drive."""

    decision_times_s: FloatArray
    truth_mps: FloatArray
    estimates_mps: dict[str, FloatArray]
    # Decision times skipped because the planner had no usable INRIX reading (no plan then).
    no_estimate_times_s: FloatArray

    def mean_absolute_error(self, variant: str) -> float:
        """MAE of one variant over the drive's decision times."""
        return float(np.mean(np.abs(self.estimates_mps[variant] - self.truth_mps)))


def probe_pings(
    drive: ProbeDrive, start_s: float, end_s: float, period_s: float
) -> tuple[FloatArray, FloatArray]:
    """The drive's samples in [start, end), thinned to one per ping period."""
    inside = np.nonzero((drive.time_s >= start_s) & (drive.time_s < end_s))[0]
    if len(inside) == 0:
        return np.zeros(0), np.zeros(0)
    slot = np.floor((drive.time_s[inside] - start_s) / period_s)
    first_in_slot = inside[np.r_[True, np.diff(slot) > 0]]
    return drive.x_m[first_in_slot], drive.speed_mps[first_in_slot]


def evaluate_drive(
    drive: ProbeDrive,
    inrix: InrixHistory,
    grid: CorridorGrid,
    params: PlannerParams | None = None,
    *,
    latency_s: float = 180.0,
    step_s: float = 10.0,
    horizon_s: float = 60.0,
    ping_period_s: float = 1.0,
    lane: int = 1,
) -> DriveErrors:
    """Every variant's TSE along the drive's next minute against the speed it drove."""
    params = params or PlannerParams()
    raw = params.model_copy(update={"predictor": "latest"})
    first = float(drive.time_s[0]) + params.ping_window_s
    last = float(drive.time_s[-1]) - horizon_s
    times = np.arange(first, last + 1e-9, step_s)
    decided: list[float] = []
    skipped: list[float] = []
    truths: list[float] = []
    estimates: dict[str, list[float]] = {variant: [] for variant in VARIANTS}
    no_pings = LaneObservations()
    for now_s in times:
        ahead = (drive.time_s >= now_s) & (drive.time_s < now_s + horizon_s)
        cells = grid.cell_of(drive.x_m[ahead])
        on_grid = cells >= 0
        if not on_grid.any():
            continue
        cells = cells[on_grid]
        visible = inrix.until(now_s - latency_s)
        x_seen, speed_seen = probe_pings(drive, now_s - params.ping_window_s, now_s, ping_period_s)
        own_pings = LaneObservations.from_pings(
            grid, np.full(len(x_seen), lane), x_seen, speed_seen
        )
        cases = {
            "inrix": (visible, no_pings, raw),
            "predicted": (visible, no_pings, params),
            "fused": (visible, own_pings, params),
            "inrix_without_latency": (inrix.until(now_s), no_pings, raw),
        }
        try:
            found = {
                variant: enhance_tse(
                    PlannerInputs(grid, history, observations, float(now_s)), variant_params
                ).tse_mps
                for variant, (history, observations, variant_params) in cases.items()
            }
        except NoInrixEstimate:
            skipped.append(float(now_s))
            continue
        decided.append(float(now_s))
        truths.append(float(drive.speed_mps[ahead][on_grid].mean()))
        for variant, tse in found.items():
            estimates[variant].append(float(tse[lane - 1, cells].mean()))
    return DriveErrors(
        decision_times_s=np.asarray(decided),
        truth_mps=np.asarray(truths),
        estimates_mps={variant: np.asarray(values) for variant, values in estimates.items()},
        no_estimate_times_s=np.asarray(skipped),
    )
