"""Choosing the deployment pair honestly: cross-validation that keeps whole dates apart.

Every candidate (planner parameters x planner x controller variant) is simulated once on every
drive; a fold then chooses, on its training dates only, the candidate with the largest mean
fuel saving on the shockwave drives among those that meet the aims (paper "Candidate Controller
Selection": neutral on throughput and network speed in shockwave, no KPI worse in freeflow):
no collision, shockwave throughput and network speed no worse than -2 %, freeflow fuel,
throughput and network speed no worse than -1 %. The chosen candidate is scored on the fold's
held-out dates, which it never saw; the held-out scores of all folds are the result. The
deployment choice is the same rule on every date (its own score is not a result).

A trained policy has seen the dates it was trained on (a row's `policy_training_dates`): its
rows of those dates are used neither to choose nor to score its fuel, throughput and speed, so
an RL candidate is judged, on either side of a fold, only on drives its weights were not fitted
to. Its collisions and takeovers count on every drive, those dates too: a policy that crashes
on its own training drives is not safe for having seen them. Candidates compared with each
other (`choose`, `candidate_summary`) are all judged on the same drives, those of dates no
candidate's policy was fitted on (`common_rows`): a mean moves with the drives it is taken over,
so a candidate judged on all 14 dates and one judged on 7 were not compared on the same traffic
(docs/simulation/selection-common-drives-preregistered.md).

Pure functions over evaluation rows (`sim.evaluate.Evaluation.rows()` plus a `candidate` key
and, for a candidate with a trained policy, `policy_training_dates`, ";"-joined).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from sim.folds import held_out_dates
from sim.kpi import measured_mean

Row = Mapping[str, Any]

SHOCKWAVE_MAX_LOSS_PCT = -2.0
FREEFLOW_MAX_LOSS_PCT = -1.0
FREEFLOW_KPIS = ("fuel_economy_mpg_change_pct", "throughput_change_pct", "network_speed_change_pct")


# A collision, or a KPI the drives cannot measure (NaN: a platoon that never moved, a drive too
# short for its tail to pass where its leader started), costs this many points of shortfall:
# never traded for fuel, and never read as an aim met.
UNMET_POINTS = 100.0


def _loss_beyond(aim_pct: float, change_pct: float) -> float:
    """How far a mean change falls below its aim (UNMET_POINTS when it is undefined)."""
    return UNMET_POINTS if math.isnan(change_pct) else max(0.0, aim_pct - change_pct)


@dataclass(frozen=True)
class Standing:
    """How a candidate did on a set of drives: the objective and how far it misses the aims."""

    candidate: str
    fuel_saving_pct: float
    shortfall_pct: float

    @property
    def meets_aims(self) -> bool:
        """No collision and no KPI beyond its allowed loss."""
        return self.shortfall_pct == 0.0


def standing(
    candidate: str,
    rows: Sequence[Row],
    scenarios: Collection[str] | None = None,
    set_aside_dates: Collection[str] | None = None,
) -> Standing:
    """The candidate's shockwave fuel saving and its total shortfall against the aims, on the
    drives it may be judged on: those not of `set_aside_dates` (default: the dates its own
    policy was fitted on, `unseen_rows`). A collision on any of its drives, a KPI left
    undefined (the saving itself included), or one of `scenarios` (default: those of its own
    rows) with no drive to judge it on counts UNMET_POINTS: no evidence is no pass."""
    required = {str(row["scenario"]) for row in rows} if scenarios is None else set(scenarios)
    judged = (
        unseen_rows(rows)
        if set_aside_dates is None
        else [row for row in rows if date_of(row) not in set_aside_dates]
    )
    shock = [row for row in judged if row["scenario"] == "shockwave"]
    free = [row for row in judged if row["scenario"] == "freeflow"]
    fuel_saving = measured_mean(shock, "fuel_saving_pct")
    shortfall = UNMET_POINTS * sum(int(row["collisions"]) for row in rows)
    if math.isnan(fuel_saving):
        shortfall += UNMET_POINTS
    if shock:
        for key in ("throughput_change_pct", "network_speed_change_pct"):
            shortfall += _loss_beyond(SHOCKWAVE_MAX_LOSS_PCT, measured_mean(shock, key))
    if free:
        for key in FREEFLOW_KPIS:
            shortfall += _loss_beyond(FREEFLOW_MAX_LOSS_PCT, measured_mean(free, key))
    elif "freeflow" in required:
        shortfall += UNMET_POINTS
    return Standing(candidate, fuel_saving, shortfall)


def _fuel_rank(standing: Standing) -> float:
    """The objective for ranking: an undefined saving ranks below every defined one."""
    saving = standing.fuel_saving_pct
    return -math.inf if math.isnan(saving) else saving


def choose(rows: Sequence[Row]) -> Standing:
    """The best candidate on these rows: the most fuel saved among those meeting the aims, or,
    when none does, the one that misses them least. Every candidate is judged on the same
    drives (`common_rows`: those of dates no candidate's policy was fitted on) and in every
    scenario any of them was run in."""
    by_candidate: dict[str, list[Row]] = {}
    for row in rows:
        by_candidate.setdefault(str(row["candidate"]), []).append(row)
    scenarios = {str(row["scenario"]) for row in rows}
    set_aside = fitted_dates(rows)
    standings = [
        standing(name, candidate_rows, scenarios, set_aside)
        for name, candidate_rows in by_candidate.items()
    ]
    if not standings:
        raise ValueError("no candidate rows to choose from")
    meeting = [s for s in standings if s.meets_aims]
    if meeting:
        return max(meeting, key=_fuel_rank)
    return min(standings, key=lambda s: (s.shortfall_pct, -_fuel_rank(s)))


@dataclass(frozen=True)
class FoldChoice:
    """One fold: the dates held out, what training chose, and its held-out rows."""

    held_out_dates: tuple[str, ...]
    chosen: Standing
    held_out_rows: tuple[Row, ...]


def date_of(row: Row) -> str:
    """The date of a row's drive (`sim.folds.drive_date`, the rows' `date`): cross-validation
    keeps each date on one side."""
    return str(row["date"])


def policy_training_dates(row: Row) -> set[str]:
    """The dates the row's candidate's trained policy was fitted on (none without a policy)."""
    return {date for date in str(row.get("policy_training_dates") or "").split(";") if date}


def fitted_on(row: Row) -> bool:
    """Whether the row's drive is of a date its candidate's trained policy was fitted on."""
    return date_of(row) in policy_training_dates(row)


def unseen_rows(rows: Iterable[Row]) -> list[Row]:
    """The rows whose drive its candidate's policy (if it has one) was not fitted on: the only
    ones whose fuel, throughput and speed may score a candidate."""
    return [row for row in rows if not fitted_on(row)]


def fitted_dates(rows: Iterable[Row]) -> set[str]:
    """Every date some candidate's policy among these rows was fitted on."""
    return set().union(*(policy_training_dates(row) for row in rows))


def common_rows(rows: Sequence[Row]) -> list[Row]:
    """The rows of the drives every candidate among them may be judged on: of dates no
    candidate's policy was fitted on. Candidates compared with each other are compared here."""
    set_aside = fitted_dates(rows)
    return [row for row in rows if date_of(row) not in set_aside]


def check_every_fold_can_choose(
    date_scenarios: Iterable[tuple[str, str]],
    folds: int,
    set_aside_dates: Collection[str] = (),
) -> None:
    """Refuse folds whose training dates hold no shockwave drive the candidates may be compared
    on: the choice is made on the shockwave drives' fuel saving (`standing`) over the dates no
    candidate's policy was fitted on (`set_aside_dates`, `common_rows`), so such a fold would
    choose on nothing and report its held-out scores as a result.

    `date_scenarios` is each run's (date, scenario); checked before anything is simulated.
    """
    pairs = list(date_scenarios)
    shockwave_dates = {date for date, scenario in pairs if scenario == "shockwave"}
    comparable = shockwave_dates - set(set_aside_dates)
    for held in held_out_dates((date for date, _ in pairs), folds):
        if not comparable - held:
            found = (
                f"the shockwave drives are of {', '.join(sorted(shockwave_dates))}"
                if shockwave_dates
                else "no drive is a shockwave one"
            )
            if shockwave_dates - held:  # there were some, but a policy was fitted on them
                found += (
                    f"; a candidate's policy was fitted on "
                    f"{', '.join(sorted(shockwave_dates - held))}"
                )
            raise ValueError(
                f"the fold holding out {', '.join(sorted(held))} keeps no shockwave drive to "
                f"choose on ({found}): give fewer folds, or drives of more dates with waves"
            )


def cross_validate(rows: Sequence[Row], folds: int) -> list[FoldChoice]:
    """Choose on the training dates of each fold, score on its held-out dates.

    The dates are dealt into folds as `sim.folds.date_folds` deals them (`held_out_dates`).
    """
    check_every_fold_can_choose(
        ((date_of(row), str(row["scenario"])) for row in rows), folds, fitted_dates(rows)
    )
    result = []
    for held in held_out_dates((date_of(row) for row in rows), folds):
        training = [row for row in rows if date_of(row) not in held]
        chosen = choose(training)
        scored = tuple(
            row for row in rows if date_of(row) in held and row["candidate"] == chosen.candidate
        )
        result.append(FoldChoice(tuple(sorted(held)), chosen, scored))
    return result


def held_out_summary(choices: Iterable[FoldChoice]) -> list[dict[str, Any]]:
    """Per scenario, the held-out rows of every fold pooled: each drive scored once, by the
    candidate chosen without its date (the KPIs over the drives it may be scored on,
    `unseen_rows`; collisions and takeovers over all of them)."""
    pooled = [row for choice in choices for row in choice.held_out_rows]
    summary = []
    for scenario in dict.fromkeys(str(row["scenario"]) for row in pooled):
        every = [row for row in pooled if row["scenario"] == scenario]
        rows = unseen_rows(every)
        summary.append(
            {
                "scenario": scenario,
                "drives": len(rows),
                "fuel_saving_pct": measured_mean(rows, "fuel_saving_pct"),
                "throughput_change_pct": measured_mean(rows, "throughput_change_pct"),
                "network_speed_change_pct": measured_mean(rows, "network_speed_change_pct"),
                "fuel_economy_mpg_change_pct": measured_mean(rows, "fuel_economy_mpg_change_pct"),
                "collisions": sum(int(row["collisions"]) for row in every),
                "takeovers": sum(int(row["takeovers"]) for row in every),
                "cut_ins": sum(int(row["cut_ins"]) for row in rows),
                "within_bounds_share": measured_mean(rows, "within_bounds_share"),
                "within_reachable_bounds_share": measured_mean(
                    rows, "within_reachable_bounds_share"
                ),
                "distance_lost_m": measured_mean(rows, "distance_lost_m"),
            }
        )
    return summary


def candidate_summary(rows: Sequence[Row]) -> list[dict[str, Any]]:
    """Every candidate on every drive, what each fold chooses from: per candidate the mean KPIs
    on the shockwave and on the freeflow drives. Context for the held-out result, not a result
    itself (the figures and any choice made from them share their drives). As in `choose`:
    the KPIs over the drives every candidate may be judged on (`common_rows`), collisions and
    takeovers over all."""
    common = common_rows(rows)
    summary = []
    for candidate in sorted({str(row["candidate"]) for row in rows}):
        every = [row for row in rows if row["candidate"] == candidate]
        own = [row for row in common if row["candidate"] == candidate]
        shock = [row for row in own if row["scenario"] == "shockwave"]
        free = [row for row in own if row["scenario"] == "freeflow"]
        summary.append(
            {
                "candidate": candidate,
                "shockwave_fuel_saving_pct": measured_mean(shock, "fuel_saving_pct"),
                "shockwave_throughput_change_pct": measured_mean(shock, "throughput_change_pct"),
                "shockwave_network_speed_change_pct": measured_mean(
                    shock, "network_speed_change_pct"
                ),
                "freeflow_fuel_saving_pct": measured_mean(free, "fuel_saving_pct"),
                "freeflow_throughput_change_pct": measured_mean(free, "throughput_change_pct"),
                "freeflow_network_speed_change_pct": measured_mean(
                    free, "network_speed_change_pct"
                ),
                "collisions": sum(int(row["collisions"]) for row in every),
                "takeovers": sum(int(row["takeovers"]) for row in every),
                "within_bounds_share": measured_mean(own, "within_bounds_share"),
                "within_reachable_bounds_share": measured_mean(
                    own, "within_reachable_bounds_share"
                ),
                "shockwave_distance_lost_m": measured_mean(shock, "distance_lost_m"),
            }
        )
    return summary
