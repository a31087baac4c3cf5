"""The evaluation scenarios of the paper's section "Candidate Controller Selection".

- shockwave: the platoon behind a real stop-and-go drive;
- freeflow: the platoon behind a real all-high-speed drive;
- bottleneck: the platoon behind a real high-speed drive through a region whose speed limit
  falls as the density of vehicles inside rises (the paper's weaving area, where on- and
  off-ramps close together force lane changes);
- shockwave_inrix: the platoon behind a real stop-and-go drive recorded with the INRIX feed of
  the same minutes, the planner reading the real feed instead of the simulated one;
- freeflow_inrix: the same behind the recorded drives that never slow into a wave (the two
  longer cuts of 2021-03-08), so every drive recorded with INRIX is in some scenario.

A scenario is one function from the available drives (plain, and recorded with INRIX) to its
cases, registered in `SCENARIOS`: a new scenario is one function and one registry line.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.drives import Drive
from sim.recorded import RecordedDrive
from sim.traffic import InrixFeed

FloatArray = NDArray[np.float64]

SECONDS_PER_HOUR = 3600.0
# Bottleneck: the limit is v = capacity / density, so the flow through the region cannot exceed
# the capacity. 1,300 veh/h per lane is below what the platoon brings behind the high-speed
# drives (1,400-1,700 veh/h at the I-24 IDM's free-flow spacing), so a queue forms; behind the
# 2021-03-09 drive it holds the platoon at 5-9 m/s inside the region (8.8 m/s on average), the
# speeds INRIX recorded in the slow segments of the 2021-03-15 drive (8-9 m/s). Free of
# traffic the region allows 70 mph.
BOTTLENECK_CAPACITY_VPH = 1300.0
BOTTLENECK_FREE_SPEED_MPS = 31.2928
BOTTLENECK_LENGTH_M = 1000.0
# The region starts halfway along the drive, so the platoon reaches it in steady free flow and
# leaves it with kilometres to spare; throughput is measured this far past its end.
BOTTLENECK_START_SHARE = 0.5
BOTTLENECK_MEASURE_AFTER_M = 100.0


@dataclass(frozen=True)
class Bottleneck:
    """A region [start_m, end_m) whose speed limit is capacity / density (and at most free)."""

    start_m: float
    end_m: float
    capacity_vph: float = BOTTLENECK_CAPACITY_VPH
    free_speed_mps: float = BOTTLENECK_FREE_SPEED_MPS

    def __post_init__(self) -> None:
        if not self.end_m > self.start_m:
            raise ValueError("a bottleneck must end after it starts")
        if self.capacity_vph <= 0 or self.free_speed_mps <= 0:
            raise ValueError("bottleneck capacity and free speed must be positive")

    @property
    def measure_point_m(self) -> float:
        """Where its throughput is measured: just downstream of the region."""
        return self.end_m + BOTTLENECK_MEASURE_AFTER_M

    @staticmethod
    def density_per_m(inside_m: FloatArray) -> float:
        """Vehicles per metre among those inside: (n - 1) over the stretch they occupy.

        Counting over the whole region would read a platoon that fills part of it as sparse
        traffic; the spacing of the vehicles present is the density they drive in.
        """
        if len(inside_m) < 2:
            return 0.0
        occupied = float(inside_m.max() - inside_m.min())
        return (len(inside_m) - 1) / occupied if occupied > 0 else float("inf")

    def limit_for_density_mps(self, vehicles_per_m: float) -> float:
        """The posted limit for a density: capacity / density, capped at the free speed."""
        if vehicles_per_m <= 0:
            return self.free_speed_mps
        if vehicles_per_m == float("inf"):
            return 0.0
        return min(self.free_speed_mps, self.capacity_vph / SECONDS_PER_HOUR / vehicles_per_m)

    def limits_mps(self, position_m: FloatArray) -> FloatArray | None:
        """Each vehicle's limit now: the region's limit inside it, none (inf) outside."""
        inside = (position_m >= self.start_m) & (position_m < self.end_m)
        count = int(np.count_nonzero(inside))
        if count == 0:
            return None
        limit = self.limit_for_density_mps(self.density_per_m(position_m[inside]))
        limits: FloatArray = np.where(inside, limit, np.inf)
        return limits


@dataclass(frozen=True)
class Case:
    """One simulation of a scenario: a leader drive and, for the bottleneck, its region."""

    scenario: str
    drive: Drive
    bottleneck: Bottleneck | None = None
    # The real INRIX minutes of the drive; None: INRIX simulated from the drive (sim.inrix).
    inrix: InrixFeed | None = None

    @property
    def name(self) -> str:
        """`scenario/drive`, as in the tables."""
        return f"{self.scenario}/{self.drive.name}"

    @property
    def measure_point_m(self) -> float | None:
        """The one point throughput is measured at (the bottleneck's, just downstream of its
        region); None: the paper's five equi-spaced points."""
        return None if self.bottleneck is None else self.bottleneck.measure_point_m


def shockwave_cases(drives: Sequence[Drive], recorded: Sequence[RecordedDrive]) -> list[Case]:
    """Every real stop-and-go drive."""
    return [Case("shockwave", drive) for drive in drives if drive.kind == "shockwave"]


def freeflow_cases(drives: Sequence[Drive], recorded: Sequence[RecordedDrive]) -> list[Case]:
    """Every real all-high-speed drive."""
    return [Case("freeflow", drive) for drive in drives if drive.kind == "freeflow"]


def bottleneck_cases(drives: Sequence[Drive], recorded: Sequence[RecordedDrive]) -> list[Case]:
    """Every high-speed drive, with a density-limited region halfway along it."""
    cases = []
    for drive in drives:
        if drive.kind != "freeflow":
            continue
        start = BOTTLENECK_START_SHARE * float(drive.position_m[-1])
        cases.append(Case("bottleneck", drive, Bottleneck(start, start + BOTTLENECK_LENGTH_M)))
    return cases


def shockwave_inrix_cases(drives: Sequence[Drive], recorded: Sequence[RecordedDrive]) -> list[Case]:
    """Every recorded stop-and-go drive, with its real INRIX minutes."""
    return [
        Case("shockwave_inrix", one.drive, inrix=one.feed)
        for one in recorded
        if one.drive.kind == "shockwave"
    ]


def freeflow_inrix_cases(drives: Sequence[Drive], recorded: Sequence[RecordedDrive]) -> list[Case]:
    """Every recorded all-high-speed drive, with its real INRIX minutes."""
    return [
        Case("freeflow_inrix", one.drive, inrix=one.feed)
        for one in recorded
        if one.drive.kind == "freeflow"
    ]


SCENARIOS: dict[str, Callable[[Sequence[Drive], Sequence[RecordedDrive]], list[Case]]] = {
    "shockwave": shockwave_cases,
    "freeflow": freeflow_cases,
    "bottleneck": bottleneck_cases,
    "shockwave_inrix": shockwave_inrix_cases,
    "freeflow_inrix": freeflow_inrix_cases,
}
# The scenarios that drive on the recordings with real INRIX (`--inrix-drives`).
RECORDED_SCENARIOS = frozenset({"shockwave_inrix", "freeflow_inrix"})


def scenario_cases(
    names: Sequence[str], drives: Sequence[Drive], recorded: Sequence[RecordedDrive] = ()
) -> list[Case]:
    """The cases of the named scenarios, in the order given."""
    unknown = [name for name in names if name not in SCENARIOS]
    if unknown:
        raise ValueError(
            f"unknown scenario {', '.join(unknown)} (known: {', '.join(sorted(SCENARIOS))})"
        )
    return [case for name in names for case in SCENARIOS[name](drives, recorded)]
