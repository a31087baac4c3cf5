"""How much room ahead a follower needs to smooth a drive's waves, against what the envelope leaves.

    .venv/bin/python -m sim.smoothing_room [--drives DIR]

A follower that drives its leader's trailing mean speed over W seconds instead of the leader's
speed (the simplest causal smoother: a wave shorter than W is flattened) lets its gap change by
the integral of (leader speed - that mean). The range of that integral is the room the follower
must have ahead to do so without touching its leader or falling back: `room_to_smooth_m`. A
wave v(t) = V + A sin(2 pi t / T) smoothed over W = T needs A T / pi (5 m/s over 60 s: 95 m).

The gap envelope the AV is judged against (`sim.gaps.GapBounds`, 7-120 m and >= 1 s) and the
safety bound a_safe that every `accel` command stays under (equilibrium gap s0 + v^2 (1/|a_min| -
1/|a_l,min|) / 2 behind a leader at the AV's speed, `rl_accel.SAFETY`) leave 120 m minus that
gap: `envelope_room_m`. Where a drive needs more room than that at a window, a follower inside
the envelope can smooth only its shorter waves. For scale, `cruise_saving_pct`: the fuel the
all-human platoon would save if every follower cruised at its own mean speed, the saving of
unlimited room. Both are properties of the drives; nothing is chosen on them.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from sim.drives import Drive, load_drives, shared_data_dir
from sim.energy import RAV4_2019
from sim.gaps import GapBounds
from sim.platoon import platoon_roles, simulate_platoon
from vehicle_agent.controllers.rl_accel import SAFETY

FloatArray = NDArray[np.float64]

WINDOWS_S = (10.0, 30.0, 60.0, 120.0)
FOLLOWERS = 25  # the evaluation's platoon: the AV's place and 24 humans behind it


def trailing_mean(speed_mps: FloatArray, window_steps: int) -> FloatArray:
    """Mean of each full window of `window_steps` samples ending at each step from the first
    full one (len(speed) - window_steps + 1 values)."""
    if window_steps < 1 or window_steps > len(speed_mps):
        raise ValueError(
            f"a window of {window_steps} steps does not fit a drive of {len(speed_mps)} steps"
        )
    total = np.cumsum(np.insert(np.asarray(speed_mps, dtype=np.float64), 0, 0.0))
    means: FloatArray = (total[window_steps:] - total[:-window_steps]) / window_steps
    return means


def room_to_smooth_m(speed_mps: FloatArray, dt_s: float, window_s: float) -> float:
    """The range of the gap a follower driving the trailing mean over `window_s` would open
    and close behind a leader driving `speed_mps`, from the first full window on."""
    steps = int(round(window_s / dt_s))
    mean = trailing_mean(speed_mps, steps)
    leader = np.asarray(speed_mps, dtype=np.float64)[steps - 1 :]
    gap_change = np.concatenate(([0.0], np.cumsum(leader - mean)[:-1] * dt_s))
    return float(gap_change.max() - gap_change.min())


def envelope_room_m(speed_mps: float, bounds: GapBounds | None = None) -> float:
    """Room between the largest gap of the envelope and the gap a_safe keeps at `speed_mps`
    behind a leader at the same speed (or the envelope's own minimum, if larger)."""
    envelope = bounds or GapBounds()
    safe_gap = SAFETY.standstill_gap_m + 0.5 * speed_mps**2 * (
        1.0 / abs(SAFETY.min_accel_mps2) - 1.0 / abs(SAFETY.lead_min_accel_mps2)
    )
    floor = max(envelope.min_gap_m, envelope.min_time_gap_s * speed_mps, safe_gap)
    return max(envelope.max_gap_m - floor, 0.0)


def cruise_saving_pct(drive: Drive) -> float:
    """Fuel per distance saved if every follower of the all-human platoon drove its own mean
    speed throughout, against the platoon as simulated (RAV4 model)."""
    run = simulate_platoon(drive, platoon_roles(FOLLOWERS, 0))
    speed = run.speed_mps[:-1, 1:]
    accel = np.diff(run.speed_mps[:, 1:], axis=0) / run.dt_s
    per_metre = RAV4_2019.fuel_rate_gps(speed, accel).sum() / speed.sum()
    mean = speed.mean(axis=0)
    cruise_per_metre = RAV4_2019.fuel_rate_gps(mean, np.zeros_like(mean)).sum() / mean.sum()
    return float(100.0 * (1.0 - cruise_per_metre / per_metre))


def main(argv: Sequence[str] | None = None) -> None:
    """Per kind of drive: the room needed at each window, the envelope's, the cruise saving."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--drives", type=Path, default=shared_data_dir() / "trajectories")
    args = parser.parse_args(argv)
    drives = load_drives(args.drives)
    say = print  # noqa: T201 (a command-line report)
    windows = " / ".join(f"{window:g}" for window in WINDOWS_S)
    say(f"room needed to drive the leader's trailing mean over W = {windows} s (m)")
    for kind in sorted({drive.kind for drive in drives}):
        chosen = [drive for drive in drives if drive.kind == kind]
        rooms = np.array(
            [[room_to_smooth_m(d.speed_mps, d.dt_s, w) for w in WINDOWS_S] for d in chosen]
        )
        envelope = np.array([envelope_room_m(float(d.speed_mps.mean())) for d in chosen])
        cruise = np.array([cruise_saving_pct(d) for d in chosen])
        say(
            f"{kind} ({len(chosen)} drives): median {_metres(np.median(rooms, axis=0))}"
            f", largest {_metres(rooms.max(axis=0))}; the envelope leaves"
            f" {np.median(envelope):.0f} m at the median drive's mean speed"
            f" ({envelope.min():.0f}-{envelope.max():.0f} m); cruising at the mean speed would"
            f" save {np.median(cruise):+.1f} % (median; {cruise.min():+.1f} to"
            f" {cruise.max():+.1f} %)"
        )
    for speed in (10.0, 20.0, 30.0):
        say(f"the envelope leaves {envelope_room_m(speed):.0f} m at {speed:g} m/s")


def _metres(values: FloatArray) -> str:
    return " / ".join(f"{value:.0f}" for value in values)


if __name__ == "__main__":
    main()
