"""Candidate evaluation (paper section "Candidate Controller Selection"): every Speed Planner
variant x Vehicle Controller variant over the scenarios, against an all-human baseline.

For each case (a scenario on one real drive) the baseline platoon is all IDM humans; each
variant puts the AV(s) in the platoon, spread through it as the paper's presets do, run by the
agent's controller with the real planner in the loop, supervised as the agent supervises itself
(a stop beyond the actuation's braking authority is handed back to the driver: a takeover), with
drivers from the next lane merging into large gaps (`sim.platoon.CutIns`). A variant's KPI change
is relative to the baseline of the same case; a scenario's change is the mean over its cases.
Fuel saving is the drop in fuel per distance, 1 - mpg_baseline / mpg_variant.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from contract.controllers import ACTUATIONS, RL_CONTROLLERS, RlParams
from sim.av import RADAR_RANGE_M, StockAcc, agent_policy
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.folds import drive_date
from sim.gaps import GapBounds, GapKpis, gap_kpis
from sim.kpi import (
    UNMEASURED_COLUMN,
    Kpis,
    change_pct,
    distance_lost_m,
    fuel_saving_pct,
    measured_mean,
    platoon_kpis,
    run_throughput_vph,
    throughput_points_m,
    unmeasured_paper_kpis,
)
from sim.plans import SimulatedPlanner
from sim.platoon import CutIns, HandBack, PlatoonRun, platoon_roles, simulate_platoon
from sim.runs import run_file_name, write_run, write_runs_index
from sim.scenarios import Case
from vehicle_agent.controllers.rl_acc import policy_path

BASELINE = "baseline"
NO_PLANNER = "-"
# KPI -> +1 when higher is better, -1 when lower is better (the heatmap's colour direction).
KPI_DIRECTION: dict[str, int] = {
    "fuel_economy_mpg": +1,
    "throughput_vph": +1,
    "network_speed_mps": +1,
    "accel_rms_mps2": -1,
    "jerk_rms_mps3": -1,
    "min_gap_m": +1,
    "min_ttc_s": +1,
}


class PolicyDatesUnknown(ValueError):
    """A trained policy whose training dates cannot be read from its manifest."""


@dataclass(frozen=True)
class ControllerVariant:
    """A controller as the roster assigns it: registry name, actuation and params."""

    controller: str
    actuation: str
    params: Mapping[str, Any] = field(default_factory=dict)
    label: str = ""

    @property
    def name(self) -> str:
        """The label, or `controller/actuation` plus its params."""
        if self.label:
            return self.label
        suffix = json.dumps(dict(self.params), sort_keys=True) if self.params else ""
        return f"{self.controller}/{self.actuation}{suffix}"

    @classmethod
    def parse(cls, text: str) -> ControllerVariant:
        """`name:actuation[:{json params}]`, e.g. `microaccel:accel:{"k": 0.4}`."""
        parts = text.split(":", 2)
        if len(parts) < 2 or not parts[0] or parts[1] not in ACTUATIONS:
            raise ValueError(
                f"controller variant {text!r}: expected NAME:ACTUATION[:JSON] with ACTUATION "
                f"one of {', '.join(ACTUATIONS)}"
            )
        params: dict[str, Any] = {}
        if len(parts) == 3:
            try:
                params = json.loads(parts[2])
            except json.JSONDecodeError as error:
                raise ValueError(f"controller variant {text!r}: params: {error}") from None
            if not isinstance(params, dict):
                raise ValueError(f"controller variant {text!r}: params must be a JSON object")
        return cls(parts[0], parts[1], params)

    def policy_training_dates(self) -> frozenset[str]:
        """The dates the variant's trained policy was fitted on (its manifest's
        `training_dates`, beside the policy file): no held-out score of it may come from a
        drive of those dates. Empty for a controller without a policy.

        PolicyDatesUnknown for a policy whose manifest is missing or names no
        `training_dates` (`smoothfleet sim train` always writes them): read as "fitted on no
        date", such a policy would be chosen and scored on the very drives it was fitted on.
        A hand-built policy fitted on no drive says so with an empty list."""
        if self.controller not in RL_CONTROLLERS:
            return frozenset()
        params = RlParams.model_validate(dict(self.params))
        manifest = policy_path(params, RL_CONTROLLERS[self.controller]).with_suffix(".json")
        try:
            recorded = json.loads(manifest.read_text(encoding="utf-8"))["training_dates"]
        except (OSError, ValueError, KeyError, TypeError):
            raise PolicyDatesUnknown(
                f"{self.name}: {manifest} names no training_dates, so which drives this policy "
                "was fitted on is unknown; write its manifest (smoothfleet sim train does), with "
                '"training_dates": [] for a policy fitted on no drive'
            ) from None
        return frozenset(str(date) for date in recorded)


@dataclass(frozen=True)
class RunResult:
    """The KPIs of one simulation."""

    case: Case
    planner: str
    controller: str
    kpis: Kpis
    plans_run: int = 0
    plans_buffered: int = 0
    avs: int = 0
    # Where every platoon vehicle ended (0 = the leader), and which columns were AVs.
    final_position_m: NDArray[np.float64] = field(default_factory=lambda: np.zeros(0))
    av_columns: tuple[int, ...] = ()
    gaps: GapKpis = GapKpis(0.0, 0.0, 0.0, 1.0, 1.0)
    takeovers: int = 0
    driver_seconds: float = 0.0
    cut_ins: int = 0
    recommended: bool = False
    # Planner cycles without INRIX, skipped as the server skips them (the AVs kept their plan).
    plans_skipped: int = 0
    # The baseline's throughput over the road locations this run shares with it (a variant's
    # throughput and its baseline's are measured at the same points: `throughput_points_m`);
    # None: the baseline's own KPI is the one to compare with.
    baseline_throughput_vph: float | None = None
    # Throughput change over the platoon's own vehicles (the cars that cut in not counted),
    # against the baseline's own at the same points (`run_throughput_vph`); NaN where the runs
    # share no stretch of road.
    own_throughput_change_pct: float = 0.0
    # Times an AV was left to its stock ACC for want of a fresh plan (the feed had stopped, or
    # had not begun), summed over the AVs, and the AV-seconds it drove so.
    plan_hand_backs: int = 0
    seconds_without_plan: float = 0.0


@dataclass(frozen=True)
class Evaluation:
    """All runs of an evaluation and their changes against the baselines."""

    results: list[RunResult]
    # Per drive name: the fuel saving of the fuel-optimal AV trajectory (sim.optimum), if known.
    optimum_fuel_saving_pct: Mapping[str, float] = field(default_factory=dict)

    @cached_property
    def _baselines(self) -> dict[str, RunResult]:
        """The all-human run of each case, by case name (every change is taken against one:
        a scan of the results per lookup made the tables quadratic in the runs)."""
        found: dict[str, RunResult] = {}
        for r in self.results:
            if r.controller == BASELINE:
                found.setdefault(r.case.name, r)
        return found

    def baseline(self, case_name: str) -> RunResult:
        """The all-human run of a case."""
        return self._baselines[case_name]

    def change_pct(self, result: RunResult, kpi: str) -> float:
        """Percentage change of a KPI against the case's baseline (throughput against the
        baseline's at the same road locations, where the run measured it there)."""
        base = getattr(self.baseline(result.case.name).kpis, kpi)
        if kpi == "throughput_vph" and result.baseline_throughput_vph is not None:
            base = result.baseline_throughput_vph
        return change_pct(float(getattr(result.kpis, kpi)), float(base))

    def fuel_saving_pct(self, result: RunResult) -> float:
        """Drop in fuel per distance against the case's baseline (`sim.kpi.fuel_saving_pct`)."""
        base = self.baseline(result.case.name).kpis.fuel_economy_mpg
        return fuel_saving_pct(base, result.kpis.fuel_economy_mpg)

    def distance_lost_m(self, result: RunResult) -> float:
        """How much further behind the leader the AVs ended than the humans in their places."""
        if not result.av_columns:
            return 0.0
        base = self.baseline(result.case.name).final_position_m
        return distance_lost_m(base, result.final_position_m, result.av_columns)

    def optimum_pct(self, result: RunResult) -> float:
        """The optimal bound's fuel saving on this run's drive, for a run the bound was made
        for: one AV on the drive as driven (NaN otherwise, and when not computed). The bound is
        per drive; a bottleneck case on the same drive, or 4 AVs on it, divided by it read
        "348 %" and "117 %" of an optimum made for another question."""
        if len(result.av_columns) != 1 or result.case.bottleneck is not None:
            return float("nan")
        return float(self.optimum_fuel_saving_pct.get(result.case.drive.name, float("nan")))

    def unmeasured(self) -> dict[str, list[str]]:
        """Per paper KPI, the cases whose all-human baseline gives no figure to compare with
        (`sim.kpi.unmeasured_paper_kpis`): every pair's change there is undefined, so those
        drives are left out of that KPI's means, for every pair alike."""
        found: dict[str, list[str]] = {}
        for result in self.results:
            if result.controller != BASELINE:
                continue
            for kpi in unmeasured_paper_kpis(result.kpis):
                found.setdefault(kpi, []).append(result.case.name)
        return found

    def variants(self) -> list[tuple[str, str, int]]:
        """(planner, controller, avs) evaluated, in run order."""
        seen: list[tuple[str, str, int]] = []
        for r in self.results:
            key = (r.planner, r.controller, r.avs)
            if r.controller != BASELINE and key not in seen:
                seen.append(key)
        return seen

    def scenarios(self) -> list[str]:
        """Scenario names, in run order."""
        return list(dict.fromkeys(r.case.scenario for r in self.results))

    def summary(self) -> list[dict[str, Any]]:
        """One row per scenario x planner x controller x AVs: mean changes over its cases."""
        rows = []
        # the per-run figures, so the means leave out what `measured_mean` leaves out
        run_rows = self.rows()
        for scenario in self.scenarios():
            for planner, controller, avs in self.variants():
                chosen = [
                    index
                    for index, r in enumerate(self.results)
                    if r.case.scenario == scenario
                    and (r.planner, r.controller, r.avs) == (planner, controller, avs)
                ]
                if not chosen:
                    continue
                runs = [self.results[index] for index in chosen]
                own_rows = [run_rows[index] for index in chosen]
                optimum = [self.optimum_pct(r) for r in runs]
                row: dict[str, Any] = {
                    "scenario": scenario,
                    "planner": planner,
                    "controller": controller,
                    "avs": avs,
                    "recommended": runs[0].recommended,
                    "cases": len(runs),
                    "fuel_saving_pct": measured_mean(own_rows, "fuel_saving_pct"),
                    "optimum_fuel_saving_pct": float(np.mean(optimum)),
                }
                for kpi in KPI_DIRECTION:
                    row[f"{kpi}_change_pct"] = measured_mean(own_rows, f"{kpi}_change_pct")
                row["plans_buffered"] = sum(r.plans_buffered for r in runs)
                row["plans_skipped"] = sum(r.plans_skipped for r in runs)
                row["plan_hand_backs"] = sum(r.plan_hand_backs for r in runs)
                row["collisions"] = sum(r.kpis.collisions for r in runs)
                row["gap_violations"] = sum(r.kpis.gap_violations for r in runs)
                row["takeovers"] = sum(r.takeovers for r in runs)
                row["cut_ins"] = sum(r.cut_ins for r in runs)
                row["max_av_gap_m"] = max(r.gaps.max_av_gap_m for r in runs)
                row["gap_out_of_bounds_s"] = float(
                    np.mean([r.gaps.gap_out_of_bounds_s for r in runs])
                )
                row["within_bounds_share"] = float(
                    np.mean([r.gaps.within_bounds_share for r in runs])
                )
                row["within_reachable_bounds_share"] = float(
                    np.mean([r.gaps.within_reachable_bounds_share for r in runs])
                )
                row["distance_lost_m"] = float(np.mean([self.distance_lost_m(r) for r in runs]))
                rows.append(row)
        return rows

    def run_file(self, result: RunResult) -> str:
        """The Parquet file of the run's trajectories (with --save-runs)."""
        return run_file_name(
            result.case.scenario,
            result.case.drive.name,
            result.planner,
            result.controller,
            result.avs,
        )

    def write_runs_index(self, directory: Path) -> Path:
        """`runs.csv` beside the runs' Parquet files."""
        return write_runs_index(
            directory,
            [
                (
                    self.run_file(r),
                    r.case.scenario,
                    r.case.drive.name,
                    r.planner,
                    r.controller,
                    r.avs,
                )
                for r in self.results
            ],
        )

    def rows(self) -> list[dict[str, Any]]:
        """One row per run (the CSV a reviewer recomputes from): identity, the paper's KPI
        changes, safety and gap figures, then every absolute KPI and change, and the paper
        KPIs the case's baseline cannot measure."""
        unmeasured = self.unmeasured()
        out = []
        for r in self.results:
            row: dict[str, Any] = {
                "scenario": r.case.scenario,
                "drive": r.case.drive.name,
                "planner": r.planner,
                "controller": r.controller,
                "avs": r.avs,
                "recommended": r.recommended,
                "fuel_saving_pct": self.fuel_saving_pct(r),
                "throughput_change_pct": self.change_pct(r, "throughput_vph"),
                "own_cars_throughput_change_pct": r.own_throughput_change_pct,
                "network_speed_change_pct": self.change_pct(r, "network_speed_mps"),
                "collisions": r.kpis.collisions,
                "takeovers": r.takeovers,
                "driver_seconds": r.driver_seconds,
                "cut_ins": r.cut_ins,
                "max_av_gap_m": r.gaps.max_av_gap_m,
                "gap_out_of_bounds_s": r.gaps.gap_out_of_bounds_s,
                "time_gap_violation_s": r.gaps.time_gap_violation_s,
                "within_bounds_share": r.gaps.within_bounds_share,
                "within_reachable_bounds_share": r.gaps.within_reachable_bounds_share,
                "distance_lost_m": self.distance_lost_m(r),
                "optimum_fuel_saving_pct": self.optimum_pct(r),
                "plans_run": r.plans_run,
                "plans_buffered": r.plans_buffered,
                "plans_skipped": r.plans_skipped,
                "plan_hand_backs": r.plan_hand_backs,
                "seconds_without_plan": r.seconds_without_plan,
                "date": drive_date(r.case.drive),
            }
            row.update(r.kpis.as_dict())
            for kpi in KPI_DIRECTION:
                row[f"{kpi}_change_pct"] = self.change_pct(r, kpi)
            row[UNMEASURED_COLUMN] = ";".join(
                kpi for kpi, cases in unmeasured.items() if r.case.name in cases
            )
            out.append(row)
        return out


def baseline_run(case: Case, vehicles: int, realism: Realism) -> PlatoonRun:
    """The case's all-human platoon of `vehicles` (its road and cut-ins are the AV runs')."""
    return simulate_platoon(
        case.drive,
        platoon_roles(vehicles, 0),
        speed_limit=case.bottleneck,
        cut_ins=realism.cut_ins,
    )


@dataclass(frozen=True)
class Realism:
    """How the AVs are judged and what the road does to them (defaults: the issue's)."""

    bounds: GapBounds = GapBounds()
    hand_back: HandBack = HandBack()
    cut_ins: CutIns | None = CutIns()
    # How far an `accel` car measures its leader for its controller (`sim.av.agent_policy`)
    accel_lead_range_m: float = RADAR_RANGE_M


RunSaver = Callable[[RunResult, PlatoonRun], None]


def run_case(
    case: Case,
    planner: str | None,
    variant: ControllerVariant | None,
    *,
    humans: int,
    avs: int,
    planner_params: Mapping[str, Any] | None = None,
    stock_acc: Callable[[], StockAcc] = SimulatedAccCar,
    realism: Realism = Realism(),
    recommended: bool = False,
    save: RunSaver | None = None,
) -> RunResult:
    """One simulation: the baseline (variant None, all humans+avs human) or the AVs, spread
    through the platoon, under planner x controller."""
    if variant is None:
        run = baseline_run(case, humans + avs, realism)
        result = RunResult(
            case,
            NO_PLANNER,
            BASELINE,
            platoon_kpis(run, throughput_points_m=throughput_points_m([run], case.measure_point_m)),
            final_position_m=run.position_m[-1],
            cut_ins=run.cut_ins,
        )
    else:
        if planner is None:
            raise ValueError("an AV variant needs a planner variant")
        schedule = SimulatedPlanner.for_drive(case.drive, planner, planner_params, case.inrix)
        policies = [
            agent_policy(
                variant.controller,
                variant.actuation,
                schedule,
                variant.params,
                stock_acc=stock_acc() if variant.actuation == "acc" else None,
                lead_state_range_m=realism.accel_lead_range_m,
            )
            for _ in range(avs)
        ]
        roles = platoon_roles(humans, avs)
        run = simulate_platoon(
            case.drive,
            roles,
            policies,
            speed_limit=case.bottleneck,
            av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
            hand_back=realism.hand_back,
            cut_ins=realism.cut_ins,
        )
        av_columns = tuple(int(i) + 1 for i in np.flatnonzero(roles))
        av_index = [column - 1 for column in av_columns]
        # the baseline again (a fraction of the AV run's cost), for the road locations both
        # runs' throughput is measured at
        baseline = baseline_run(case, humans + avs, realism)
        points = throughput_points_m([run, baseline], case.measure_point_m)
        result = RunResult(
            case,
            planner,
            variant.name,
            platoon_kpis(run, throughput_points_m=points),
            schedule.plans_run,
            schedule.plans_buffered,
            avs=avs,
            final_position_m=run.position_m[-1],
            av_columns=av_columns,
            gaps=gap_kpis(
                run.gap_m[:, av_index],
                run.speed_mps[:, list(av_columns)],
                run.position_m[:, list(av_columns)],
                run.dt_s,
                realism.bounds,
            ),
            takeovers=run.takeovers,
            driver_seconds=run.driver_seconds,
            cut_ins=run.cut_ins,
            recommended=recommended,
            plans_skipped=schedule.plans_skipped,
            plan_hand_backs=sum(policy.plan_hand_backs for policy in policies),
            seconds_without_plan=sum(policy.steps_without_plan for policy in policies) * run.dt_s,
            baseline_throughput_vph=(
                None if points is None else run_throughput_vph(baseline, points)
            ),
            own_throughput_change_pct=(
                float("nan")
                if points is None
                else change_pct(
                    run_throughput_vph(run, points, cut_ins_counted=False),
                    run_throughput_vph(baseline, points, cut_ins_counted=False),
                )
            ),
        )
    if save is not None:
        save(result, run)
    return result


@dataclass(frozen=True)
class Job:
    """One run of a case: the baseline (planner and variant None) or a pair with its AVs."""

    planner: str | None
    variant: ControllerVariant | None
    avs: int
    recommended: bool = False


def _run_jobs(
    case: Case,
    jobs: Sequence[Job],
    followers: int,
    planner_params: Mapping[str, Any] | None,
    realism: Realism,
    save_dir: Path | None,
) -> list[RunResult]:
    def save(result: RunResult, run: PlatoonRun) -> None:
        assert save_dir is not None
        name = run_file_name(
            result.case.scenario,
            result.case.drive.name,
            result.planner,
            result.controller,
            result.avs,
        )
        write_run(save_dir, name, run)

    results = []
    for job in jobs:
        avs = job.avs if job.variant is not None else 0
        result = run_case(
            case,
            job.planner,
            job.variant,
            humans=followers - job.avs if job.variant is not None else followers,
            avs=avs,
            planner_params=planner_params,
            realism=realism,
            recommended=job.recommended,
            save=save if save_dir is not None else None,
        )
        results.append(result)
    return results


def evaluate(
    cases: Sequence[Case],
    planners: Sequence[str],
    controllers: Sequence[ControllerVariant],
    *,
    humans: int = 24,
    avs: int | Sequence[int] = 1,
    planner_params: Mapping[str, Any] | None = None,
    recommended: tuple[str, ControllerVariant] | None = None,
    realism: Realism = Realism(),
    save_dir: Path | None = None,
    workers: int = 1,
    progress: Callable[[str], None] | None = None,
) -> Evaluation:
    """Baseline and every planner x controller x AV count on every case.

    The platoon has `humans + max(avs)` followers whatever the AV count (AVs replace humans);
    `recommended` marks that pair. Cases run in `workers` processes; `progress` hears each
    finished case. With `save_dir`, every run's trajectories are written there (sim.runs).
    """
    counts = [avs] if isinstance(avs, int) else list(avs)
    if not counts or min(counts) < 1:
        raise ValueError("every AV count must be at least 1")
    followers = humans + max(counts)
    jobs = [Job(None, None, 0)]
    jobs += [
        Job(planner, variant, count, recommended == (planner, variant))
        for count in counts
        for planner in planners
        for variant in controllers
    ]
    results: list[RunResult] = []
    if workers <= 1:
        for case in cases:
            results += _run_jobs(case, jobs, followers, planner_params, realism, save_dir)
            if progress is not None:
                progress(case.name)
    else:
        # The longest drives go first, so no core is left alone with a long case at the end;
        # the results keep the cases' order.
        longest_first = sorted(range(len(cases)), key=lambda index: -cases[index].drive.steps)
        finished: dict[int, list[RunResult]] = {}
        pool = ProcessPoolExecutor(max_workers=workers)
        try:
            futures = {
                pool.submit(
                    _run_jobs, cases[index], jobs, followers, planner_params, realism, save_dir
                ): index
                for index in longest_first
            }
            for future in as_completed(futures):
                index = futures[future]
                finished[index] = future.result()
                if progress is not None:
                    progress(cases[index].name)
        except BaseException:
            # stopped (SIGTERM, Ctrl-C) or failed: the cases not begun are dropped; leaving
            # the pool's block waited for every one of them (10 min past a `timeout 120`)
            pool.shutdown(wait=True, cancel_futures=True)
            raise
        pool.shutdown()
        for index in range(len(cases)):
            results += finished[index]
    return Evaluation(results)


def default_workers() -> int:
    """One process per core the machine gives this program."""
    return max(1, len(os.sched_getaffinity(0)))


class OptimumFileError(ValueError):
    """A file that is not `smoothfleet sim optimum`'s CSV; the message names it and why."""


@dataclass(frozen=True, slots=True)
class OptimumBound:
    """One drive's row of `smoothfleet sim optimum`'s CSV: its saving and what it was computed
    on. A file written before the provenance columns has None in both."""

    fuel_saving_pct: float
    # `Drive.fingerprint` of the speeds the bound was computed on.
    drive_fingerprint: str | None
    # Vehicles behind the leader in the bound's platoon (its AV and humans).
    followers: int | None


def load_optimum(path: Path) -> dict[str, OptimumBound]:
    """Drive name -> optimal bound from `smoothfleet sim optimum`'s CSV.

    A file without the `drive` and `fuel_saving_pct` columns, without a row, or with a saving
    that is no number is refused: read as it stands, it would leave every "of optimum" n/a
    without a word. So is a row whose `humans` is no whole number."""
    import csv

    bounds: dict[str, OptimumBound] = {}
    # utf-8-sig: a spreadsheet's byte-order mark is no part of the first column's name
    with path.open(newline="", encoding="utf-8-sig") as handle:
        reader = csv.DictReader(handle)
        try:
            columns = reader.fieldnames or []
        except UnicodeDecodeError as error:
            raise OptimumFileError(f"{path}: not UTF-8 text ({error.reason})") from None
        missing = [name for name in ("drive", "fuel_saving_pct") if name not in columns]
        if missing:
            raise OptimumFileError(
                f"{path}: not a `sim optimum` CSV (no column {' or '.join(missing)})"
            )
        for row in reader:
            saving = row["fuel_saving_pct"]
            if row["drive"] in bounds:
                # two bounds for one drive: which one was meant is no guess to make
                raise OptimumFileError(
                    f"{path}, line {reader.line_num}: drive {row['drive']} again"
                )
            try:
                saving_pct = float(saving)
            except (TypeError, ValueError):
                raise OptimumFileError(
                    f"{path}, line {reader.line_num}: fuel_saving_pct {saving!r} is not a number"
                ) from None
            humans = row.get("humans") or None
            if humans is not None and not humans.isdigit():
                raise OptimumFileError(
                    f"{path}, line {reader.line_num}: humans {humans!r} is not a whole number"
                )
            bounds[row["drive"]] = OptimumBound(
                fuel_saving_pct=saving_pct,
                drive_fingerprint=row.get("drive_fingerprint") or None,
                # the bound's platoon: its one AV and the humans behind it
                followers=None if humans is None else int(humans) + 1,
            )
    if not bounds:
        raise OptimumFileError(f"{path}: no drive's bound in it")
    return bounds
