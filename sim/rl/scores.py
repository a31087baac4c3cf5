"""Held-out scores of a controller: the issue's targets, per drive and per group of drives.

Each drive is run twice, as in `sim.evaluate`: all humans (the baseline), then one AV right behind
the leader (4 % penetration with 24 humans, the paper's 1 in 25) run by the agent's controller with
the real planner in the loop. Per drive: the fuel saving of the simulated vehicles, throughput over
every vehicle and network speed against the baseline, collisions, and the share of time the AV
keeps the gap envelope (`sim.gaps`). Groups: the stop-and-go drives (2nd speed percentile below
10 m/s), every shockwave drive, the freeflow drives.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from contract.controllers import RlParams
from sim.av import AgentPolicy
from sim.drives import Drive
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.folds import drive_date
from sim.gaps import GapBounds, gap_kpis
from sim.kpi import (
    Kpis,
    change_pct,
    distance_lost_m,
    fuel_saving_pct,
    measured_mean,
    measured_values,
    platoon_kpis,
    run_throughput_vph,
    throughput_points_m,
    unmeasured_paper_kpis,
)
from sim.plans import SimulatedPlanner
from sim.platoon import CutIns, HandBack, PlatoonRun, platoon_roles, simulate_platoon
from vehicle_agent.controllers import AccClip, Controller, build_controller
from vehicle_agent.controllers.rl_acc import RlAccController
from vehicle_agent.controllers.rl_accel import RlAccelController

# A stop-and-go drive: its 2nd speed percentile is below this (m/s; the definition).
STOP_AND_GO_P2_MPS = 10.0


@dataclass(frozen=True)
class ControllerUnderTest:
    """A controller to score: a label for the tables, its actuation, and how to build one."""

    label: str
    actuation: str
    build: Callable[[], Controller]

    @classmethod
    def registered(
        cls, name: str, actuation: str, params: Mapping[str, Any]
    ) -> ControllerUnderTest:
        """A controller of the agent's registry, built as the agent builds it."""
        return cls(name, actuation, lambda: build_controller(name, actuation, params))

    @classmethod
    def policy_file(cls, label: str, actuation: str, path: Path) -> ControllerUnderTest:
        """An RL controller running the policy in `path` (behind the ACC clip on `acc` cars)."""
        params = RlParams(policy=str(path))

        def build() -> Controller:
            if actuation == "acc":
                return AccClip(RlAccController("acc", params))
            return RlAccelController("accel", params)

        return cls(label, actuation, build)


@dataclass(frozen=True)
class DriveScore:
    """One controller on one drive, against the all-human platoon of the same drive."""

    drive: str
    date: str
    kind: str
    stop_and_go: bool
    controller: str
    fuel_saving_pct: float
    throughput_change_pct: float
    network_speed_change_pct: float
    accel_rms_change_pct: float
    collisions: int
    gap_within_share: float
    # The paper KPIs the all-human platoon of this drive cannot measure (`sim.kpi.
    # UNMEASURED_COLUMN`): left out of those KPIs' group means for every controller alike.
    # Empty in manifests written before the field existed (no shared drive needed it).
    unmeasured_by_baseline: str = ""
    # The share within the envelope judged to the reachable leader (`sim.gaps`): what of the
    # time outside the fleet's top speed leaves the AV no way to avoid. NaN in manifests written
    # before the field existed.
    gap_within_reachable_share: float = math.nan
    # How much further behind the leader the AV ended than the human in its place (as
    # `sim evaluate`'s distance lost): what a policy that drops back gives away. NaN in
    # manifests written before the field existed.
    distance_lost_m: float = math.nan
    # The AV's hand-backs to its driver (`sim.platoon.HandBack`, as `sim evaluate` counts them)
    # and the seconds the driver drove. None and NaN in manifests written before 2026-12-05,
    # whose runs had no hand-back: an AV that needed its driver scored as if it had not.
    takeovers: int | None = None
    driver_seconds: float = math.nan

    def as_dict(self) -> dict[str, Any]:
        """Plain values (manifest, CSV)."""
        return asdict(self)


def is_stop_and_go(drive: Drive) -> bool:
    """A drive whose 2nd speed percentile is below 10 m/s."""
    return float(np.percentile(drive.speed_mps, 2.0)) < STOP_AND_GO_P2_MPS


def simulate_one_av(
    drive: Drive,
    entry: ControllerUnderTest,
    *,
    planner: str,
    planner_params: Mapping[str, Any],
    humans: int = 24,
    cut_ins: CutIns | None = None,
) -> PlatoonRun:
    """The drive with one AV right behind the leader, run by `entry` with the real planner in
    the loop (its ACC car on `acc`), and `humans` I-24 IDM drivers behind it; with `cut_ins`,
    cars from the next lane merge into wide gaps as in `sim evaluate`. The agent hands the AV
    back to its driver as in `sim evaluate` (`HandBack`): without it, the scores that choose
    restarts and reward weights saw an AV brake where its driver would have taken over, and
    counted no takeover (rl_acc on 2021-04-05: 0 here, 2 in `sim evaluate`)."""
    schedule = SimulatedPlanner.for_drive(drive, planner, planner_params)
    policy = AgentPolicy(
        entry.build(),
        schedule,
        senses_lead_state=entry.actuation == "accel",
        stock_acc=SimulatedAccCar() if entry.actuation == "acc" else None,
    )
    return simulate_platoon(
        drive,
        platoon_roles(humans, 1),
        [policy],
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
        cut_ins=cut_ins,
        hand_back=HandBack(),
    )


def scoring_progress(
    progress: Callable[[str, int, int], None] | None, stage: str, total: int
) -> Callable[[str], None] | None:
    """`score_drives`' per-run callback reported as `progress(stage, runs done, total)`."""
    if progress is None:
        return None
    counter = itertools.count(1)

    def scored(label: str) -> None:
        progress(stage, next(counter), total)

    return scored


def score_drives(
    drives: Sequence[Drive],
    controllers: Sequence[ControllerUnderTest],
    *,
    planner: str,
    planner_params: Mapping[str, Any],
    humans: int = 24,
    bounds: GapBounds | None = None,
    cut_ins: CutIns | None = None,
    progress: Callable[[str], None] | None = None,
) -> list[DriveScore]:
    """Every controller on every drive (one AV behind the leader, `humans` behind it), with
    `cut_ins` in both the AV's and the all-human platoon, as `sim evaluate` has them."""
    envelope = bounds or GapBounds()
    scores = []
    for drive in drives:
        base_run = simulate_platoon(drive, platoon_roles(humans + 1, 0), cut_ins=cut_ins)
        base = platoon_kpis(base_run)
        for entry in controllers:
            run = simulate_one_av(
                drive,
                entry,
                planner=planner,
                planner_params=planner_params,
                humans=humans,
                cut_ins=cut_ins,
            )
            scores.append(score_run(drive, entry.label, base_run, base, run, envelope))
            if progress is not None:
                progress(f"{drive.name} {entry.label}")
    return scores


def score_run(
    drive: Drive,
    label: str,
    base_run: PlatoonRun,
    base: Kpis,
    run: PlatoonRun,
    envelope: GapBounds,
) -> DriveScore:
    """One run with AVs against the all-human run of the same drive (`base`, its KPIs): both
    runs' throughput at the same road locations (`sim.kpi.shared_points_m`), the envelope and
    the distance lost judged over every AV of the run."""
    points = throughput_points_m([run, base_run])
    kpis = platoon_kpis(run, throughput_points_m=points)
    base_throughput = (
        base.throughput_vph if points is None else run_throughput_vph(base_run, points)
    )
    av = np.flatnonzero(run.is_av[1:])
    envelope_kpis = gap_kpis(
        run.gap_m[:, av], run.speed_mps[:, av + 1], run.position_m[:, av + 1], run.dt_s, envelope
    )
    lost_m = distance_lost_m(base_run.position_m[-1], run.position_m[-1], (av + 1).tolist())
    return DriveScore(
        drive=drive.name,
        date=drive_date(drive),
        kind=drive.kind,
        stop_and_go=is_stop_and_go(drive),
        controller=label,
        fuel_saving_pct=fuel_saving_pct(base.fuel_economy_mpg, kpis.fuel_economy_mpg),
        throughput_change_pct=change_pct(kpis.throughput_vph, base_throughput),
        network_speed_change_pct=change_pct(kpis.network_speed_mps, base.network_speed_mps),
        accel_rms_change_pct=change_pct(kpis.accel_rms_mps2, base.accel_rms_mps2),
        collisions=kpis.collisions,
        gap_within_share=envelope_kpis.within_bounds_share,
        unmeasured_by_baseline=";".join(unmeasured_paper_kpis(base)),
        gap_within_reachable_share=envelope_kpis.within_reachable_bounds_share,
        distance_lost_m=lost_m,
        takeovers=run.takeovers,
        driver_seconds=run.driver_seconds,
    )


GROUPS: dict[str, Callable[[DriveScore], bool]] = {
    "stop_and_go": lambda score: score.stop_and_go,
    "shockwave": lambda score: score.kind == "shockwave",
    "freeflow": lambda score: score.kind == "freeflow",
}


def group_mean(scores: Sequence[DriveScore], column: str) -> float:
    """The mean of a drive-score column by the project's one rule (`sim.kpi.measured_mean`):
    a drive whose all-human platoon cannot measure the column's KPI is left out; one the
    controller left undefined makes the mean NaN."""
    return measured_mean([score.as_dict() for score in scores], column)


def group_worst(scores: Sequence[DriveScore], column: str) -> float:
    """The least of the same drives' values; NaN, as their mean, when one is undefined (the
    builtin `min` would return NaN or skip it depending on where it stands in the list)."""
    values = measured_values([score.as_dict() for score in scores], column)
    if not values or not all(math.isfinite(value) for value in values):
        return float("nan")
    return min(values)


def _total_takeovers(scores: Sequence[DriveScore]) -> int | None:
    """The takeovers over `scores`; None when any was scored without the hand-back."""
    counts = [score.takeovers for score in scores]
    return None if None in counts else sum(count for count in counts if count is not None)


def summarise(scores: Sequence[DriveScore]) -> list[dict[str, Any]]:
    """Per controller and group: mean fuel saving, mean and worst throughput and network speed
    changes (drives the all-human platoon cannot measure left out), collisions, takeovers, the
    smallest share of time within the gap envelope, the mean distance lost."""
    rows = []
    for label in dict.fromkeys(score.controller for score in scores):
        for group, member in GROUPS.items():
            chosen = [s for s in scores if s.controller == label and member(s)]
            if not chosen:
                continue
            rows.append(
                {
                    "controller": label,
                    "group": group,
                    "drives": len(chosen),
                    "fuel_saving_pct": group_mean(chosen, "fuel_saving_pct"),
                    "throughput_change_pct": group_mean(chosen, "throughput_change_pct"),
                    "worst_throughput_change_pct": group_worst(chosen, "throughput_change_pct"),
                    "network_speed_change_pct": group_mean(chosen, "network_speed_change_pct"),
                    "worst_network_speed_change_pct": group_worst(
                        chosen, "network_speed_change_pct"
                    ),
                    "collisions": sum(s.collisions for s in chosen),
                    "takeovers": _total_takeovers(chosen),
                    "min_gap_within_share": min(s.gap_within_share for s in chosen),
                    "min_gap_within_reachable_share": group_worst(
                        chosen, "gap_within_reachable_share"
                    ),
                    "distance_lost_m": group_mean(chosen, "distance_lost_m"),
                }
            )
    return rows
