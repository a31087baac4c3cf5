"""`smoothfleet sim evaluate`: every planner x controller pair against the all-human baseline on
the real drives, as a table, a CSV and a heatmap."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.av import RADAR_RANGE_M
from sim.evaluate import (
    BASELINE,
    Evaluation,
    OptimumFileError,
    Realism,
    default_workers,
    evaluate,
    load_optimum,
)
from sim.platoon import HandBack
from sim.recommended import RECOMMENDED_CONTROLLER
from sim.report import (
    MAX_LOSS_PCT,
    best_pair,
    markdown_table,
    summary_table,
    write_csv,
    write_heatmap,
)
from sim.scenarios import RECORDED_SCENARIOS, SCENARIOS, Case
from smoothfleet.cli.common import output_folder, write_output, write_output_with
from smoothfleet.cli.sim.shared import (
    chosen_cases,
    console,
    controller_variants,
    default_folder,
    drives_option,
    progress_bar,
    read_drives,
    read_recorded_drives,
)

DEFAULT_SCENARIOS = tuple(SCENARIOS)


class IntListOption(click.Option):
    """An option followed by one or more integers: `--avs 1 2 4 8` (or `--avs 1,2`)."""

    def add_to_parser(self, parser: Any, ctx: click.Context) -> None:
        super().add_to_parser(parser, ctx)
        for name in self.opts:
            option = parser._long_opt.get(name) or parser._short_opt.get(name)
            if option is None:
                continue
            original = option.process

            def greedy(value: str, state: Any, original: Any = original) -> None:
                values = [value]
                while state.rargs and state.rargs[0].replace(",", "").isdigit():
                    values.append(state.rargs.pop(0))
                original(" ".join(values), state)

            option.process = greedy

    def type_cast_value(self, ctx: click.Context, value: Any) -> list[int]:
        if value is None:
            return [1]
        try:
            counts = [int(part) for part in str(value).replace(",", " ").split()]
        except ValueError:
            raise click.BadParameter(
                f"{value!r}: AV counts are whole numbers, e.g. --avs 1 2 4 8", ctx, self
            ) from None
        if not counts or min(counts) < 1 or max(counts) > 100:
            raise click.BadParameter(f"{value!r}: each AV count is 1 to 100", ctx, self)
        return sorted(set(counts))


def _read_optimum(path: Path, cases: Sequence[Case], followers: int) -> dict[str, float]:
    """The bound's fuel saving per drive from `--optimum`, and how many of the drives it
    covers (a drive recorded with its INRIX has none, `sim optimum` runs on the trajectories
    only).

    A bound computed on other speeds than the drive evaluated under its name (another cut or
    version of the drive), or for a platoon of another length, is refused: its "of optimum"
    would compare a controller with another road's bound. A file written before the bounds
    recorded what they were computed on is matched by drive name, and the command says so."""
    try:
        optimum = load_optimum(path)
    except OptimumFileError as error:
        raise click.BadParameter(str(error), param_hint="--optimum") from None
    evaluated = {case.drive.name: case.drive for case in cases}
    covered = sorted(evaluated.keys() & optimum.keys())
    for name in covered:
        bound = optimum[name]
        if bound.drive_fingerprint not in (None, evaluated[name].fingerprint):
            raise click.BadParameter(
                f"the bound for {name} was computed on other speeds than the drive of that name "
                f"evaluated here (fingerprint {bound.drive_fingerprint}, the drive's "
                f"{evaluated[name].fingerprint}): another cut or version of the drive",
                param_hint="--optimum",
            )
        if bound.followers not in (None, followers):
            raise click.BadParameter(
                f"the bound for {name} is for {bound.followers} vehicles behind the leader, "
                f"this evaluation's platoon has {followers} (--vehicles)",
                param_hint="--optimum",
            )
    console.print(
        f"--optimum: a bound for {len(covered)} of the {len(evaluated)} drives "
        'evaluated (the others\' "of optimum" is n/a)'
    )
    unchecked = [name for name in covered if optimum[name].drive_fingerprint is None]
    if unchecked:
        console.print(
            f"--optimum: {len(unchecked)} of those bounds do not record the speeds or platoon "
            "they were computed on (written before `sim optimum` did): matched by drive name only"
        )
    return {name: bound.fuel_saving_pct for name, bound in optimum.items()}


def _planner_params(text: str | None) -> dict[str, Any]:
    if text is None:
        return dict(RECOMMENDED_PLANNER_PARAMS)
    try:
        params = json.loads(text)
    except json.JSONDecodeError as error:
        raise click.BadParameter(f"not JSON: {error}", param_hint="--planner-params") from None
    if not isinstance(params, dict):
        raise click.BadParameter("must be a JSON object", param_hint="--planner-params")
    return params


@click.command("evaluate")
@drives_option("Folder of real drive CSVs (10 Hz)")
@click.option(
    "--inrix-drives",
    "inrix_dir",
    type=click.Path(path_type=Path),
    default=lambda: default_folder("trajectories_with_inrix"),
    help="Folder of drives recorded with their INRIX minutes (scenarios shockwave_inrix, "
    "freeflow_inrix) "
    "[default: shared/data/trajectories_with_inrix beside the checkout].",
)
@click.option(
    "--scenario",
    "scenarios",
    multiple=True,
    type=click.Choice(sorted(SCENARIOS)),
    help="Scenario to run (repeatable; default: all).",
)
@click.option(
    "--planner",
    "planners",
    multiple=True,
    help="Planner algorithm (repeatable; default: every registered one).",
)
@click.option(
    "--controller",
    "controllers",
    multiple=True,
    help='Controller variant NAME:ACTUATION[:JSON params], e.g. microaccel:accel:{"k":0.4} '
    "(repeatable; default: every registered controller on each actuation, and the "
    "recommended variant).",
)
@click.option(
    "--recommended",
    is_flag=True,
    help="Evaluate the recommended pair alone (sim/recommended.py) against the baseline.",
)
@click.option(
    "--planner-params",
    default=None,
    help="Planner parameters as JSON [default: the recommended pair's].",
)
@click.option(
    "--vehicles",
    "followers",
    default=25,
    show_default=True,
    type=click.IntRange(2, 1000),
    help="Vehicles behind the leader (AVs replace humans among them).",
)
@click.option(
    "--avs",
    cls=IntListOption,
    default="1",
    show_default=True,
    help="AV counts, spread evenly through the platoon (e.g. --avs 1 2 4 8: one AV in 25, in "
    "~12, in ~6, in ~3), each reported side by side.",
)
@click.option(
    "--optimum",
    "optimum_csv",
    type=click.Path(path_type=Path, exists=True, dir_okay=False),
    help="CSV of `smoothfleet sim optimum`: each drive's optimal bound, for the share column.",
)
@click.option(
    "--reaction-time",
    "reaction_time_s",
    type=click.FloatRange(0.0, 3.9),
    default=HandBack().reaction_time_s,
    show_default=True,
    help="Seconds a driver takes to brake after a hand-back, the stock ACC braking meanwhile "
    "(sim.platoon.HandBack).",
)
@click.option(
    "--accel-lead-range",
    "accel_lead_range_m",
    type=click.FloatRange(1.0, 300.0),
    default=RADAR_RANGE_M,
    show_default=True,
    help="Metres to which an accel car (the RAV4, which reports leaders to 252 m) measures its "
    "leader for its controller's bound; a policy's features still read none past 100 m.",
)
@click.option(
    "--save-runs",
    "runs_dir",
    type=click.Path(path_type=Path, file_okay=False),
    help="Write every run's trajectories (Parquet) and runs.csv into this folder.",
)
@click.option(
    "--workers",
    type=click.IntRange(1, 64),
    default=default_workers,
    show_default="one per core",
    help="Processes running cases side by side.",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path("sim_results"),
    show_default=True,
    help="Where evaluation.csv, heatmap.png and summary.md go.",
)
def evaluate_command(
    drives_dir: Path | None,
    inrix_dir: Path | None,
    scenarios: tuple[str, ...],
    planners: tuple[str, ...],
    controllers: tuple[str, ...],
    recommended: bool,
    planner_params: str | None,
    followers: int,
    avs: list[int],
    optimum_csv: Path | None,
    reaction_time_s: float,
    accel_lead_range_m: float,
    runs_dir: Path | None,
    workers: int,
    out_dir: Path,
) -> None:
    """Baseline (all human) and every planner x controller over the scenarios."""
    from planner import ALGORITHMS

    if recommended and (planners or controllers):
        raise click.UsageError("--recommended evaluates the recommended pair alone")
    variants = [RECOMMENDED_CONTROLLER] if recommended else controller_variants(controllers)
    chosen_planners = [RECOMMENDED_PLANNER] if recommended else list(planners)
    chosen_planners = chosen_planners or ALGORITHMS.names()
    unknown = [name for name in chosen_planners if name not in ALGORITHMS]
    if unknown:
        raise click.BadParameter(
            f"unknown planner {', '.join(unknown)} (known: {', '.join(ALGORITHMS.names())})",
            param_hint="--planner",
        )
    params = _planner_params(planner_params)
    if max(avs) >= followers:
        raise click.BadParameter(
            f"{max(avs)} AVs leave no human in a platoon of {followers}", param_hint="--avs"
        )
    chosen = list(scenarios) or list(DEFAULT_SCENARIOS)
    context = click.get_current_context()
    given = click.core.ParameterSource.DEFAULT, click.core.ParameterSource.DEFAULT_MAP
    own_drives = context.get_parameter_source("drives_dir") not in given
    own_recordings = context.get_parameter_source("inrix_dir") not in given
    if own_drives and not own_recordings and not scenarios:
        # A folder of new drives is evaluated alone: the shared recordings of the default
        # --inrix-drives came along and filled the table's *_inrix rows with drives that were
        # not the folder's.
        chosen = [name for name in chosen if name not in RECORDED_SCENARIOS]
        console.print(
            f"--drives {drives_dir}: its drives only (scenarios {', '.join(chosen)}); give "
            "--inrix-drives or --scenario for the drives recorded with their INRIX minutes"
        )
    on_recordings = bool(RECORDED_SCENARIOS.intersection(chosen))
    if drives_dir is None or (inrix_dir is None and on_recordings):
        raise click.ClickException(
            "no shared data found beside the checkout: pass --drives and --inrix-drives, or "
            "set SMOOTHFLEET_SHARED_DATA"
        )
    drives = read_drives(drives_dir)
    recorded = read_recorded_drives(inrix_dir) if on_recordings and inrix_dir is not None else []
    cases = chosen_cases(chosen, drives, recorded)
    optimum = _read_optimum(optimum_csv, cases, followers) if optimum_csv is not None else {}
    output_folder(out_dir, "--out")
    if runs_dir is not None:
        output_folder(runs_dir, "--save-runs")
    with progress_bar() as progress:
        task = progress.add_task("simulating", total=len(cases))

        def advance(label: str) -> None:
            progress.update(task, advance=1, description=label[:60])

        try:
            evaluation = evaluate(
                cases,
                chosen_planners,
                variants,
                humans=followers - max(avs),
                avs=avs,
                planner_params=params,
                recommended=(RECOMMENDED_PLANNER, RECOMMENDED_CONTROLLER),
                realism=Realism(
                    hand_back=HandBack(reaction_time_s=reaction_time_s),
                    accel_lead_range_m=accel_lead_range_m,
                ),
                save_dir=runs_dir,
                workers=workers,
                progress=advance,
            )
        except ValueError as error:
            raise click.ClickException(str(error)) from None
    evaluation = Evaluation(evaluation.results, optimum)
    write_output_with(out_dir / "evaluation.csv", lambda path: write_csv(evaluation, path))
    write_output_with(out_dir / "heatmap.png", lambda path: write_heatmap(evaluation, path))
    write_output(out_dir / "summary.md", markdown_table(evaluation))
    if runs_dir is not None:
        evaluation.write_runs_index(runs_dir)
        console.print(f"wrote {len(evaluation.results)} runs to {runs_dir}")
    console.print(summary_table(evaluation))
    for kpi, unmeasured in evaluation.unmeasured().items():
        console.print(
            f"{kpi}: the all-human platoon gives no figure on {len(unmeasured)} drive(s), left "
            f"out of that KPI's means for every pair alike: {', '.join(unmeasured)}"
        )
    without_plan = [result for result in evaluation.results if result.plan_hand_backs]
    if without_plan:
        console.print(
            "runs whose AVs were left without a fresh plan (the INRIX feed began late or "
            f"stopped): {len(without_plan)}; hand-backs to the stock ACC: "
            f"{sum(r.plan_hand_backs for r in without_plan)}; AV-seconds driven on it: "
            f"{sum(r.seconds_without_plan for r in without_plan):.0f} (plan_hand_backs, "
            "seconds_without_plan in evaluation.csv)"
        )
    best = best_pair(evaluation)
    if not any(result.case.scenario == "shockwave" for result in evaluation.results):
        console.print("the best pair is named on the shockwave scenario, which was not run")
    elif best is None and not _judgeable_on_shockwave(evaluation):
        # a drive too short for the platoon's tail to pass, or a leader that never moves: the
        # aims cannot be judged, which is not the same as every pair missing them
        console.print(
            "no pair is named: throughput, network speed or fuel is not measured on these "
            "shockwave drives (the lines above say which)"
        )
    elif best is None:
        console.print(
            f"no pair kept throughput and speed within {MAX_LOSS_PCT:.0f} % on shockwave "
            "without a collision"
        )
    else:
        console.print(
            f"best on shockwave (throughput and speed within {MAX_LOSS_PCT:.0f} %, no collision): "
            f"{best['planner']} x {best['controller']} ({best['avs']} AV): fuel saving "
            f"{best['fuel_saving_pct']:+.1f} %, throughput "
            f"{best['throughput_vph_change_pct']:+.1f} %, network speed "
            f"{best['network_speed_mps_change_pct']:+.1f} %, collisions {best['collisions']}, "
            f"takeovers {best['takeovers']}"
        )
    console.print(f"wrote {out_dir / 'evaluation.csv'}, {out_dir / 'heatmap.png'}")


def _judgeable_on_shockwave(evaluation: Evaluation) -> bool:
    """Whether some pair's shockwave row has every figure the best pair is judged on."""
    keys = ("throughput_vph_change_pct", "network_speed_mps_change_pct", "fuel_saving_pct")
    return any(
        all(math.isfinite(row[key]) for key in keys)
        for row in evaluation.summary()
        if row["scenario"] == "shockwave" and row["controller"] != BASELINE
    )
