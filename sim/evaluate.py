"""Candidate evaluation (paper section "Candidate Controller Selection"): every Speed Planner
variant x Vehicle Controller variant over the scenarios, against an all-human baseline.

For each case (a scenario on one real drive) the baseline platoon is all IDM humans; each
variant puts the AV(s) in the platoon, run by the agent's controller with the real planner in
the loop. A variant's KPI change is relative to the baseline of the same case; a scenario's
change is the mean over its cases. Fuel saving is the drop in fuel per distance,
1 - mpg_baseline / mpg_variant.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim.av import StockAcc, agent_policy
from sim.emulator.acc import SimulatedAccCar
from sim.energy import RAV4_2019
from sim.kpi import Kpis, platoon_kpis
from sim.plans import SimulatedPlanner
from sim.platoon import PlatoonRun, platoon_roles, simulate_platoon
from sim.scenarios import Case

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
PAPER_KPIS = ("fuel_economy_mpg", "throughput_vph", "network_speed_mps")


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
        if len(parts) < 2 or not parts[0] or parts[1] not in ("acc", "accel"):
            raise ValueError(
                f"controller variant {text!r}: expected NAME:ACTUATION[:JSON] with ACTUATION "
                "acc or accel"
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


@dataclass(frozen=True)
class RunResult:
    """The KPIs of one simulation."""

    case: Case
    planner: str
    controller: str
    kpis: Kpis
    plans_run: int = 0
    plans_buffered: int = 0


@dataclass(frozen=True)
class Evaluation:
    """All runs of an evaluation and their changes against the baselines."""

    results: list[RunResult]

    def baseline(self, case_name: str) -> RunResult:
        """The all-human run of a case."""
        return next(
            r for r in self.results if r.case.name == case_name and r.controller == BASELINE
        )

    def change_pct(self, result: RunResult, kpi: str) -> float:
        """Percentage change of a KPI against the case's baseline."""
        base = getattr(self.baseline(result.case.name).kpis, kpi)
        value = getattr(result.kpis, kpi)
        if base == 0 or not np.isfinite(base) or not np.isfinite(value):
            return float("nan")
        return float(100.0 * (value / base - 1.0))

    def fuel_saving_pct(self, result: RunResult) -> float:
        """Drop in fuel per distance against the baseline (positive = less fuel)."""
        base = self.baseline(result.case.name).kpis.fuel_economy_mpg
        return float(100.0 * (1.0 - base / result.kpis.fuel_economy_mpg))

    def variants(self) -> list[tuple[str, str]]:
        """(planner, controller) pairs evaluated, in run order."""
        seen: list[tuple[str, str]] = []
        for r in self.results:
            pair = (r.planner, r.controller)
            if r.controller != BASELINE and pair not in seen:
                seen.append(pair)
        return seen

    def scenarios(self) -> list[str]:
        """Scenario names, in run order."""
        return list(dict.fromkeys(r.case.scenario for r in self.results))

    def summary(self) -> list[dict[str, Any]]:
        """One row per scenario x planner x controller: mean KPI changes over its cases."""
        rows = []
        for scenario in self.scenarios():
            for planner, controller in self.variants():
                runs = [
                    r
                    for r in self.results
                    if r.case.scenario == scenario
                    and r.planner == planner
                    and r.controller == controller
                ]
                if not runs:
                    continue
                row: dict[str, Any] = {
                    "scenario": scenario,
                    "planner": planner,
                    "controller": controller,
                    "cases": len(runs),
                    "fuel_saving_pct": float(np.mean([self.fuel_saving_pct(r) for r in runs])),
                }
                for kpi in KPI_DIRECTION:
                    row[f"{kpi}_change_pct"] = float(
                        np.mean([self.change_pct(r, kpi) for r in runs])
                    )
                row["plans_buffered"] = sum(r.plans_buffered for r in runs)
                row["collisions"] = sum(r.kpis.collisions for r in runs)
                row["gap_violations"] = sum(r.kpis.gap_violations for r in runs)
                rows.append(row)
        return rows

    def rows(self) -> list[dict[str, Any]]:
        """One row per run: absolute KPIs and changes against its baseline (the CSV)."""
        out = []
        for r in self.results:
            row: dict[str, Any] = {
                "scenario": r.case.scenario,
                "drive": r.case.drive.name,
                "planner": r.planner,
                "controller": r.controller,
                "plans_run": r.plans_run,
                "plans_buffered": r.plans_buffered,
            }
            row.update(r.kpis.as_dict())
            row["fuel_saving_pct"] = self.fuel_saving_pct(r)
            for kpi in KPI_DIRECTION:
                row[f"{kpi}_change_pct"] = self.change_pct(r, kpi)
            out.append(row)
        return out


def case_kpis(case: Case, run: PlatoonRun) -> Kpis:
    """A run's KPIs; the bottleneck's throughput is measured just downstream of its region."""
    point = case.bottleneck.measure_point_m if case.bottleneck is not None else None
    return platoon_kpis(run, throughput_point_m=point)


def run_case(
    case: Case,
    planner: str | None,
    variant: ControllerVariant | None,
    *,
    humans: int,
    avs: int,
    planner_params: Mapping[str, Any] | None = None,
    stock_acc: Callable[[], StockAcc] = SimulatedAccCar,
) -> RunResult:
    """One simulation: the baseline (variant None) or the AVs under planner x controller."""
    if variant is None:
        run = simulate_platoon(
            case.drive, platoon_roles(humans + avs, 0), speed_limit=case.bottleneck
        )
        return RunResult(case, NO_PLANNER, BASELINE, case_kpis(case, run))
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
        )
        for _ in range(avs)
    ]
    run = simulate_platoon(
        case.drive,
        platoon_roles(humans, avs),
        policies,
        speed_limit=case.bottleneck,
        av_max_accel=lambda v: float(RAV4_2019.max_accel_mps2(v)),
    )
    return RunResult(
        case,
        planner,
        variant.name,
        case_kpis(case, run),
        schedule.plans_run,
        schedule.plans_buffered,
    )


def evaluate(
    cases: Sequence[Case],
    planners: Sequence[str],
    controllers: Sequence[ControllerVariant],
    *,
    humans: int = 24,
    avs: int = 1,
    planner_params: Mapping[str, Any] | None = None,
    stock_acc: Callable[[], StockAcc] = SimulatedAccCar,
    progress: Callable[[str], None] | None = None,
) -> Evaluation:
    """Baseline and every planner x controller on every case; `progress` hears each run."""
    results = []
    for case in cases:
        jobs: list[tuple[str | None, ControllerVariant | None]] = [(None, None)]
        jobs += [(planner, variant) for planner in planners for variant in controllers]
        for planner, variant in jobs:
            results.append(
                run_case(
                    case,
                    planner,
                    variant,
                    humans=humans,
                    avs=avs,
                    planner_params=planner_params,
                    stock_acc=stock_acc,
                )
            )
            if progress is not None:
                label = variant.name if variant is not None else BASELINE
                progress(f"{case.name} {planner or NO_PLANNER} {label}")
    return Evaluation(results)
