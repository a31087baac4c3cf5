"""`smoothfleet sim ...`: run the candidate evaluation on the real drives from the command line."""

from __future__ import annotations

import json
import math
import shlex
import sys
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from planner.params import InvalidParams, PlannerParams
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import (
    FREEFLOW_MIN_SPEED_MPS,
    FREEFLOW_PERCENTILE,
    MAX_FILLED_GAP_S,
    STEP_S,
    Drive,
    DriveError,
    load_drive,
    load_drives,
    shared_data_dir,
)
from sim.evaluate import (
    BASELINE,
    ControllerVariant,
    Evaluation,
    OptimumFileError,
    PolicyDatesUnknown,
    Realism,
    RunResult,
    default_workers,
    evaluate,
    load_optimum,
    run_case,
)
from sim.folds import drive_date
from sim.platoon import CutIns, HandBack, PlatoonRun
from sim.recommended import RECOMMENDED_CONTROLLER, registered_variants
from sim.recorded import RecordedDrive, load_recorded_drives
from sim.report import (
    MAX_LOSS_PCT,
    best_pair,
    markdown_table,
    percent_text,
    summary_table,
    write_csv,
    write_heatmap,
    write_rows,
    write_time_space,
)
from sim.scenarios import RECORDED_SCENARIOS, SCENARIOS, Case, scenario_cases
from sim.selection import (
    candidate_summary,
    check_every_fold_can_choose,
    choose,
    cross_validate,
    held_out_summary,
)
from smoothfleet.cli.common import (
    FiniteFloatRange,
    fleet_options,
    output_file,
    output_folder,
    write_output,
    write_output_with,
)
from vehicle_agent.controllers.registry import build_controller

# Wide enough for the evaluation table when the output is a file or a pipe.
console = Console(width=max(Console().width, 160))

DEFAULT_SCENARIOS = tuple(SCENARIOS)


def progress_bar() -> Progress:
    """The bar every long `sim` command shows: what runs, how far, how long."""
    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        console=console,
        transient=True,
    )


@click.group("sim")
def sim() -> None:
    """Simulate platoons on real I-24 drives: evaluate planners x controllers."""


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


def _controller_variants(texts: tuple[str, ...]) -> list[ControllerVariant]:
    """The variants named, each built once as the agent builds it (its parameters checked, its
    policy file read), so a mistake is named before any drive is simulated."""
    try:
        variants = [ControllerVariant.parse(text) for text in texts]
        for variant in variants:
            build_controller(variant.controller, variant.actuation, variant.params)
    except ValueError as error:  # ControllerConfigError and PolicyFileError among them
        raise click.BadParameter(str(error), param_hint="--controller") from None
    return variants or registered_variants()


def _read_optimum(path: Path, cases: Sequence[Case]) -> dict[str, float]:
    """The bound per drive from `--optimum`, and how many of the drives it covers (a drive
    recorded with its INRIX has none, `sim optimum` runs on the trajectories only)."""
    try:
        optimum = load_optimum(path)
    except OptimumFileError as error:
        raise click.BadParameter(str(error), param_hint="--optimum") from None
    drives = {case.drive.name for case in cases}
    console.print(
        f"--optimum: a bound for {len(drives & optimum.keys())} of the {len(drives)} drives "
        'evaluated (the others\' "of optimum" is n/a)'
    )
    return optimum


def _read_drives(drives_dir: Path) -> list[Drive]:
    """The folder's drives, or a ClickException naming the file and row that cannot be
    replayed; a drive whose missing samples were filled is named, with how much was filled."""
    try:
        drives = load_drives(drives_dir)
    except DriveError as error:
        raise click.ClickException(str(error)) from None
    _say_filled(drives)
    return drives


def _read_recorded_drives(inrix_dir: Path) -> list[RecordedDrive]:
    """`_read_drives` for the drives recorded with their INRIX minutes."""
    try:
        recorded = load_recorded_drives(inrix_dir)
    except DriveError as error:
        raise click.ClickException(str(error)) from None
    _say_filled([one.drive for one in recorded])
    return recorded


def _say_filled(drives: Sequence[Drive]) -> None:
    for drive in drives:
        if drive.filled_s > 0.0:
            console.print(
                f"{drive.name}: {drive.filled_s:.1f} s between samples off the "
                f"{STEP_S:g} s grid, filled by linear interpolation (gaps up to "
                f"{MAX_FILLED_GAP_S:g} s are)"
            )


def _scenario_cases(
    chosen: Sequence[str], drives: Sequence[Drive], recorded: Sequence[RecordedDrive] = ()
) -> list[Case]:
    """The cases of the chosen scenarios, or a ClickException saying why there are none (the
    drives given are all of the other kind): an evaluation of nothing has no table to write."""
    cases = scenario_cases(chosen, drives, recorded)
    if cases:
        return cases
    kinds = Counter(drive.kind for drive in drives)
    found = ", ".join(f"{count} {kind}" for kind, count in sorted(kinds.items())) or "none"
    recorded_kinds = Counter(one.drive.kind for one in recorded)
    if recorded_kinds:
        found += "; recorded with INRIX: " + ", ".join(
            f"{count} {kind}" for kind, count in sorted(recorded_kinds.items())
        )
    raise click.ClickException(
        f"no drive falls in scenario {', '.join(chosen)} (drives found: {found}; a drive is "
        f"freeflow when under {FREEFLOW_PERCENTILE:g} % of its time is below "
        f"{FREEFLOW_MIN_SPEED_MPS:g} m/s, else shockwave)"
    )


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


def _default_folder(name: str) -> Path | None:
    try:
        return shared_data_dir() / name
    except DriveError:
        return None


def _drives_option(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """`--drives`: the folder of real drives a command reads, the shared data's by default."""
    return click.option(
        "--drives",
        "drives_dir",
        type=click.Path(path_type=Path),
        default=lambda: _default_folder("trajectories"),
        help=f"{what} [default: shared/data/trajectories beside the checkout, or "
        "$SMOOTHFLEET_SHARED_DATA].",
    )


@sim.command("evaluate")
@_drives_option("Folder of real drive CSVs (10 Hz)")
@click.option(
    "--inrix-drives",
    "inrix_dir",
    type=click.Path(path_type=Path),
    default=lambda: _default_folder("trajectories_with_inrix"),
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
    runs_dir: Path | None,
    workers: int,
    out_dir: Path,
) -> None:
    """Baseline (all human) and every planner x controller over the scenarios."""
    from planner import ALGORITHMS

    if recommended and (planners or controllers):
        raise click.UsageError("--recommended evaluates the recommended pair alone")
    variants = [RECOMMENDED_CONTROLLER] if recommended else _controller_variants(controllers)
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
    on_recordings = bool(RECORDED_SCENARIOS.intersection(chosen))
    if drives_dir is None or (inrix_dir is None and on_recordings):
        raise click.ClickException(
            "no shared data found beside the checkout: pass --drives and --inrix-drives, or "
            "set SMOOTHFLEET_SHARED_DATA"
        )
    drives = _read_drives(drives_dir)
    recorded = _read_recorded_drives(inrix_dir) if on_recordings and inrix_dir is not None else []
    cases = _scenario_cases(chosen, drives, recorded)
    optimum = _read_optimum(optimum_csv, cases) if optimum_csv is not None else {}
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
                realism=Realism(hand_back=HandBack(reaction_time_s=reaction_time_s)),
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


# Candidates `sim select` adds to the registered pairs: the gains the evaluation found to matter.
SELECTION_VARIANTS = (
    'microaccel:accel:{"k": 0.2}',
    'microaccel:accel:{"k": 0.05}',
    'microaccel_acc:acc:{"base": {"k": 0.05}}',
)


@sim.command("select")
@_drives_option("Folder of real drive CSVs (10 Hz)")
@click.option(
    "--window",
    "windows",
    multiple=True,
    type=FiniteFloatRange(min=100),
    help="Planner smoothing window (m) to try (repeatable; default 1500 and 4000).",
)
@click.option(
    "--engaged-pings",
    "engaged_pings_rules",
    multiple=True,
    type=click.Choice(["all", "behind_leader"]),
    help="Planner rule for engaged cars' pings to try (repeatable; default both).",
)
@click.option(
    "--controller",
    "controllers",
    multiple=True,
    help="Controller variant to try (repeatable; default: every registered one plus "
    + ", ".join(SELECTION_VARIANTS)
    + ").",
)
@click.option("--folds", default=7, show_default=True, type=click.IntRange(2, 100))
@click.option(
    "--workers",
    type=click.IntRange(1, 64),
    default=default_workers,
    show_default="one per core",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path("sim_selection"),
    show_default=True,
    help="Where selection.csv (every candidate's runs) and held_out.csv go.",
)
def select_command(
    drives_dir: Path | None,
    windows: tuple[float, ...],
    engaged_pings_rules: tuple[str, ...],
    controllers: tuple[str, ...],
    folds: int,
    workers: int,
    out_dir: Path,
) -> None:
    """Choose the deployment pair by cross-validation keeping whole dates apart."""
    if drives_dir is None:
        raise click.ClickException("no shared data found beside the checkout: pass --drives")
    variants = (
        _controller_variants(controllers)
        if controllers
        else [
            *registered_variants(),
            *(ControllerVariant.parse(text) for text in SELECTION_VARIANTS),
        ]
    )
    variants = list({variant.name: variant for variant in variants}.values())
    try:
        fitted_dates = {variant.name: variant.policy_training_dates() for variant in variants}
    except PolicyDatesUnknown as error:
        raise click.BadParameter(str(error), param_hint="--controller") from None
    drives = _read_drives(drives_dir)
    cases = _scenario_cases(["shockwave", "freeflow"], drives)
    try:
        check_every_fold_can_choose(
            ((drive_date(case.drive), case.scenario) for case in cases), folds
        )
    except ValueError as error:
        raise click.BadParameter(str(error), param_hint="--folds") from None
    candidates = [
        {**RECOMMENDED_PLANNER_PARAMS, "window_m": window, "engaged_pings": rule}
        for window in windows or (1500.0, 4000.0)
        for rule in engaged_pings_rules or ("all", "behind_leader")
    ]
    for params in candidates:  # before anything is simulated
        try:
            PlannerParams.parse(params)
        except InvalidParams as error:
            raise click.BadParameter(str(error), param_hint="--window") from None
    output_folder(out_dir, "--out")
    rows: list[dict[str, Any]] = []
    for params in candidates:
        setting = _planner_setting(params)
        with progress_bar() as progress:
            task = progress.add_task(setting, total=len(cases))

            def advance(label: str, task: TaskID = task) -> None:
                progress.update(task, advance=1)

            evaluation = evaluate(
                cases,
                [RECOMMENDED_PLANNER],
                variants,
                planner_params=params,
                workers=workers,
                progress=advance,
            )
        for row in evaluation.rows():
            if row["controller"] != BASELINE:
                row["candidate"] = f"{row['planner']} x {row['controller']} @ {setting}"
                row["policy_training_dates"] = ";".join(sorted(fitted_dates[row["controller"]]))
                rows.append(row)
    choices = cross_validate(rows, folds)
    table = Table(title=f"{folds}-fold cross-validation over dates: choice on training dates")
    for column in ("held-out dates", "chosen on the other dates", "train fuel saving", "meets"):
        table.add_column(column)
    for choice in choices:
        table.add_row(
            ", ".join(choice.held_out_dates),
            choice.chosen.candidate,
            percent_text(choice.chosen.fuel_saving_pct),
            "yes" if choice.chosen.meets_aims else f"no (short {choice.chosen.shortfall_pct:.1f})",
        )
    console.print(table)
    summary = held_out_summary(choices)
    console.print(
        _summary_table(
            "Held-out drives only (each scored by the pair chosen without its date)", summary
        )
    )
    console.print(
        _summary_table(
            "Every candidate on every drive (what the folds choose from: context, not a result)",
            candidate_summary(rows),
        )
    )
    deployed = choose(rows)
    console.print(
        f"chosen on every date (the deployment pair; its score here is not a result): "
        f"{deployed.candidate}"
    )
    write_output_with(out_dir / "selection.csv", lambda path: write_rows(rows, path))
    write_output_with(out_dir / "held_out.csv", lambda path: write_rows(summary, path))
    console.print(f"wrote {out_dir / 'selection.csv'}, {out_dir / 'held_out.csv'}")


def _share_text(share: float) -> str:
    """A share of time in % for people; "n/a" where it is undefined."""
    return f"{100 * share:.1f} %" if math.isfinite(share) else "n/a"


def _planner_setting(params: Mapping[str, Any]) -> str:
    """A candidate's planner setting as the selection names it: the window, and the
    `engaged_pings` rule when it is not the paper's (every ping fused)."""
    setting = f"{float(params['window_m']):.0f} m"
    if params["engaged_pings"] != "all":
        setting += f", engaged pings {params['engaged_pings']}"
    return setting


def _summary_table(title: str, lines: Sequence[Mapping[str, Any]]) -> Table:
    """Summary rows as a table, one column per key, floats signed to two decimals."""
    table = Table(title=title)
    for column in lines[0]:
        table.add_column(column)
    for line in lines:
        table.add_row(
            *(
                f"{value:+.2f}" if isinstance(value, float) else str(value)
                for value in line.values()
            )
        )
    return table


@sim.command("time-space")
@click.option(
    "--drive",
    "drive_path",
    type=click.Path(path_type=Path, exists=True, dir_okay=False),
    default=lambda: _default_folder("trajectories/2021-03-15-12-46-38_masterArray_0_8314.csv"),
    help="Real drive CSV [default: a stop-and-go drive of 2021-03-15 from the shared data].",
)
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True)
def time_space_command(drive_path: Path | None, output: Path) -> None:
    """All-human platoon vs the recommended pair on one drive, as time-space diagrams."""
    if drive_path is None:
        raise click.ClickException("no shared data found beside the checkout: pass --drive")
    try:
        drive = load_drive(drive_path)
    except DriveError as error:
        raise click.ClickException(str(error)) from None
    output_file(output, "--output")
    case = Case("shockwave", drive)
    runs: dict[str, PlatoonRun] = {}

    def keep(result: RunResult, run: PlatoonRun) -> None:
        runs[result.controller] = run

    baseline = run_case(case, None, None, humans=25, avs=0, save=keep)
    chosen = run_case(
        case,
        RECOMMENDED_PLANNER,
        RECOMMENDED_CONTROLLER,
        humans=24,
        avs=1,
        planner_params=RECOMMENDED_PLANNER_PARAMS,
        save=keep,
    )
    evaluation = Evaluation([baseline, chosen])
    label = (
        f"{RECOMMENDED_PLANNER} x {RECOMMENDED_CONTROLLER.name}\nfuel saving "
        f"{percent_text(evaluation.fuel_saving_pct(chosen))}, network speed "
        f"{percent_text(evaluation.change_pct(chosen, 'network_speed_mps'))}, "
        f"{chosen.cut_ins} cut-ins, {chosen.takeovers} takeovers"
    )
    write_output_with(
        output,
        lambda path: write_time_space(
            [("all human\n(25 IDM drivers)", runs[BASELINE]), (label, runs[chosen.controller])],
            path,
            f"{drive.name}: leader + 25 followers (the AV thick, cars merging in dashed)",
        ),
    )
    console.print(f"{label}\nwrote {output}")


@sim.command("fleet")
@click.option(
    "--server",
    "server_url",
    required=True,
    help="Base URL of a running smoothfleet API, e.g. http://api:8000.",
)
@fleet_options
def fleet_command(server_url: str, duration: float | None, vehicles: int) -> None:
    """A simulated fleet and INRIX feed against a running server (docker compose `fleet`).

    Every car runs the real vehicle agent on its own virtual CAN bus with a car emulator and
    its own token, issued in the database the server uses (SMOOTHFLEET_DATABASE_URL).
    """
    from smoothfleet.cli.common import CliError, database, settings
    from smoothfleet.cli.demo import DemoError, new_run_dir, run_fleet

    current = settings()
    with database(current) as url:
        try:
            summary = run_fleet(
                url,
                current,
                server_url.rstrip("/"),
                run_dir=new_run_dir(current),
                duration_s=duration,
                vehicles=vehicles,
                say=console.print,
            )
        except DemoError as error:
            raise CliError(f"sim fleet: {error}") from None
    for line in summary.lines():
        console.print(line)


@sim.command("train")
@click.option(
    "--actuation",
    type=click.Choice(["acc", "accel"]),
    required=True,
    help="acc: ACC speed setting and gap bars (Rogue, XT5); accel: acceleration (RAV4).",
)
@_drives_option("Folder of real drive CSVs (10 Hz) to train and cross-validate on")
@click.option("--timesteps", type=click.IntRange(min=1), default=300_000, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--folds",
    type=click.IntRange(min=2),
    default=2,
    show_default=True,
    help="Cross-validation folds; each holds out whole dates.",
)
@click.option(
    "--final/--no-final",
    default=True,
    show_default=True,
    help="Ship a policy trained on every date (else fold 0's policy).",
)
@click.option("--num-envs", type=click.IntRange(1, 256), default=16, show_default=True)
@click.option(
    "--restarts",
    type=click.IntRange(1, 16),
    default=1,
    show_default=True,
    help="Train each policy from this many seeds (--seed, --seed + 1, ...) and keep the one "
    "that drops back least on its own training drives (sim.rl.restarts).",
)
@click.option(
    "--accel-action",
    type=click.Choice(["request", "request_time_margin"]),
    default="request",
    show_default=True,
    help="accel policies: an acceleration request under a_safe, or a request and a time "
    "margin (0-1.5 s) a_safe adds to its gap.",
)
@click.option(
    "--accel-observation",
    type=click.Choice(["radar", "commanded_accel"]),
    default="radar",
    show_default=True,
    help="accel policies: the paper's observation with the radar's gap and relative speed, "
    "or that and the acceleration the agent's limiter last let through.",
)
@click.option(
    "--gamma",
    type=FiniteFloatRange(0.0, 1.0, max_open=True),
    default=None,
    help="PPO's discount per 0.1 s step: how far ahead a reward still counts "
    "[default: PpoSettings', 0.995, about 20 s].",
)
@click.option(
    "--humans",
    type=click.IntRange(1, 200),
    default=24,
    show_default=True,
    help="IDM drivers behind the AV in training.",
)
@click.option("--episode-s", type=FiniteFloatRange(min=1.0), default=300.0, show_default=True)
@click.option(
    "--cut-ins/--no-cut-ins",
    default=True,
    show_default=True,
    help="Cars from the next lane merge into the AV's gap in training, as `sim evaluate` has "
    "them (sim.platoon.CutIns); --no-cut-ins trains as every policy before 2026-12-03 was.",
)
@click.option(
    "--recorded-inrix",
    is_flag=True,
    help="Also train on the drives recorded with their INRIX minutes (--inrix-drives), each "
    "on its real feed, each training only on those of its own dates "
    "[default: every plan from simulated INRIX, as every policy before 2026-12-04 was].",
)
@click.option(
    "--inrix-drives",
    "inrix_dir",
    type=click.Path(path_type=Path),
    default=lambda: _default_folder("trajectories_with_inrix"),
    help="Folder of drives recorded with their INRIX minutes, read with --recorded-inrix "
    "[default: shared/data/trajectories_with_inrix beside the checkout].",
)
@click.option(
    "--reward-candidates",
    default=None,
    help='JSON list of reward weight changes, e.g. \'[{"fuel": 0.6}, {"accel": 0.3}]\': '
    "each fold chooses between the defaults and these on its own training dates "
    "(sim.rl.reward_selection) [default: the defaults, no selection].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path("policies"),
    show_default=True,
    help="Where rl_<actuation>.npz, its manifest .json and the fold policies go.",
)
def train_command(
    actuation: str,
    drives_dir: Path | None,
    timesteps: int,
    seed: int,
    folds: int,
    final: bool,
    num_envs: int,
    restarts: int,
    accel_action: str,
    accel_observation: str,
    gamma: float | None,
    humans: int,
    episode_s: float,
    cut_ins: bool,
    recorded_inrix: bool,
    inrix_dir: Path | None,
    reward_candidates: str | None,
    out_dir: Path,
) -> None:
    """Train the RL controller with PPO (paper, ACC-Based Controller), cross-validated by date.

    Needs the `train` extra (torch, stable-baselines3, gymnasium).
    """
    if drives_dir is None:
        raise click.ClickException("no shared data found beside the checkout: pass --drives")
    try:
        from sim.rl.env import EnvConfig
        from sim.rl.pipeline import run_training
        from sim.rl.reward_selection import RewardCandidateError, parse_reward_candidates
        from sim.rl.train import PpoSettings
    except ImportError as error:
        raise click.ClickException(
            f"sim train needs the train extra (pip install -e '.[train]'): {error}"
        ) from None
    if recorded_inrix and inrix_dir is None:
        raise click.ClickException(
            "no shared data found beside the checkout: pass --inrix-drives with --recorded-inrix"
        )
    drives = _read_drives(drives_dir)
    recorded = _read_recorded_drives(inrix_dir) if recorded_inrix and inrix_dir is not None else []
    try:
        config = EnvConfig(
            "acc" if actuation == "acc" else "accel",
            "request_time_margin" if accel_action == "request_time_margin" else "request",
            "commanded_accel" if accel_observation == "commanded_accel" else "radar",
            humans=humans,
            episode_s=episode_s,
            cut_ins=CutIns() if cut_ins else None,
        )
    except ValueError as error:
        raise click.ClickException(str(error)) from None
    try:
        candidates = parse_reward_candidates(reward_candidates) if reward_candidates else []
    except RewardCandidateError as error:
        raise click.BadParameter(str(error), param_hint="--reward-candidates") from None
    settings = PpoSettings(num_envs=num_envs)
    if gamma is not None:
        settings = replace(settings, gamma=gamma)
    output_folder(out_dir, "--out")
    with progress_bar() as progress:
        tasks: dict[str, TaskID] = {}

        def advance(stage: str, done: int, total: int) -> None:
            if stage not in tasks:
                tasks[stage] = progress.add_task(stage, total=total)
            progress.update(tasks[stage], completed=done)

        try:
            result = run_training(
                drives,
                config,
                settings,
                timesteps=timesteps,
                seed=seed,
                folds=folds,
                out_dir=out_dir,
                final=final,
                reward_candidates=candidates,
                recorded=recorded,
                restarts=restarts,
                command=shlex.join(["smoothfleet", *sys.argv[1:]]),
                progress=advance,
            )
        except ValueError as error:
            raise click.ClickException(str(error)) from None
    console.print(
        "held out (each fold's policy on the dates it was not trained on; one AV behind the "
        "leader, simulated INRIX, cut-ins as in training, no hand-backs: sim select and sim "
        "evaluate, which have them, give the verdict):"
    )
    for row in result.summary:
        console.print(
            f"{row['controller']:>15} {row['group']:>12} ({row['drives']} drives): fuel saving "
            f"{percent_text(row['fuel_saving_pct'])}, throughput "
            f"{percent_text(row['throughput_change_pct'])} (worst "
            f"{percent_text(row['worst_throughput_change_pct'])}), network speed "
            f"{percent_text(row['network_speed_change_pct'])} (worst "
            f"{percent_text(row['worst_network_speed_change_pct'])}), collisions "
            f"{row['collisions']}, gap within bounds >= {100 * row['min_gap_within_share']:.1f} %"
            f" (to the reachable leader >= {_share_text(row['min_gap_within_reachable_share'])})"
            f", distance lost {row['distance_lost_m']:+.0f} m"
        )
    console.print(
        f"wrote {result.policy_path} (sha256 {result.sha256[:12]}) and {result.manifest_path}"
    )


@sim.command("optimum")
@_drives_option("Folder of real drive CSVs (10 Hz)")
@click.option(
    "--drive",
    "names",
    multiple=True,
    help="Only the drive with this name (file name without .csv; repeatable).",
)
@click.option("--humans", default=24, show_default=True, type=click.IntRange(0, 1000))
@click.option(
    "--control-interval",
    default=1.0,
    show_default=True,
    type=FiniteFloatRange(min=0.1),
    help="Seconds each piece of the piecewise-constant AV acceleration lasts.",
)
@click.option(
    "--start-smoothing",
    "starts",
    multiple=True,
    default=(0.0,),
    show_default=True,
    type=FiniteFloatRange(min=0.0),
    help="Start the descent from the leader's speed averaged over this many seconds "
    "(0: from the AV driving as the humans do); repeatable: each drive's bound is the best "
    "start's.",
)
@click.option(
    "--max-iterations",
    type=click.IntRange(min=1),
    default=None,
    help="L-BFGS-B iterations per penalty stage, the search's budget (four stages) "
    "[default: OptimumSettings', 400].",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(path_type=Path),
    default=Path("sim_results"),
    show_default=True,
    help="Where optimum.csv and the per-drive cache (optimum/) go.",
)
def optimum_command(
    drives_dir: Path | None,
    names: tuple[str, ...],
    humans: int,
    control_interval: float,
    starts: tuple[float, ...],
    max_iterations: int | None,
    out_dir: Path,
) -> None:
    """The fuel-optimal AV trajectory per drive (the bound of every controller's saving).

    Each drive's result is cached in OUT/optimum/ per start (reused while the drive and the
    settings are the same); OUT/optimum.csv gets one row per drive, its best start's
    (`sim.optimum.best_row`), rewritten after each drive. A drive with no bound (its leader
    never moves) is named at the end, after the others are done.
    """
    try:
        from sim.optimum import (
            OptimumSettings,
            best_row,
            cache_key,
            load_cached_row,
            optimal_trajectory,
            save_cached,
            write_optimum_csv,
        )
    except ImportError as error:
        raise click.ClickException(
            f"sim optimum needs the optimize extra (pip install -e '.[optimize]'): {error}"
        ) from None
    from sim.energy import RAV4_2019
    from sim.gaps import GapBounds

    if drives_dir is None:
        raise click.ClickException(
            "no shared data found beside the checkout: pass --drives, or set "
            "SMOOTHFLEET_SHARED_DATA"
        )
    drives = _read_drives(drives_dir)
    if names:
        unknown = sorted(set(names) - {drive.name for drive in drives})
        if unknown:
            raise click.BadParameter(
                f"no drive {', '.join(unknown)} in {drives_dir}", param_hint="--drive"
            )
        drives = [drive for drive in drives if drive.name in names]
    budget = OptimumSettings().max_iterations if max_iterations is None else max_iterations
    every_start = [
        OptimumSettings(
            control_interval_s=control_interval, max_iterations=budget, start_smoothing_s=start
        )
        for start in dict.fromkeys(starts)
    ]
    bounds = GapBounds()
    cache = output_folder(out_dir / "optimum", "--out")
    rows = []
    # Each drive's saving from every start, printed beside its bound.
    by_start: dict[str, list[str]] = {}
    # Drives that have no bound (a leader that never moves): named at the end, the others done.
    refused: list[str] = []
    with progress_bar() as progress:
        task = progress.add_task("optimising", total=len(drives) * len(every_start))
        for drive in drives:
            progress.update(task, description=drive.name[:60])
            solved: list[dict[str, str | float | int]] = []
            for settings in every_start:
                start = settings.start_smoothing_s
                key = cache_key(drive, humans, bounds, settings, RAV4_2019)
                row = load_cached_row(cache, drive.name, key, start)
                if row is None:
                    try:
                        result = optimal_trajectory(
                            drive, humans=humans, bounds=bounds, settings=settings
                        )
                    except ValueError as error:
                        refused.append(str(error))
                        progress.advance(task, len(every_start) - len(solved))
                        break
                    row = save_cached(cache, result, key)
                solved.append(row)
                progress.advance(task)
            if len(solved) < len(every_start):
                continue
            by_start[drive.name] = [
                f"{float(row['fuel_saving_pct']):+.2f} % from {float(row['start_smoothing_s']):g} s"
                for row in solved
            ]
            rows.append(best_row(solved))
            write_output_with(out_dir / "optimum.csv", lambda path: write_optimum_csv(rows, path))
    for row in rows:
        console.print(
            f"{row['drive']}: fuel saving {float(row['fuel_saving_pct']):+.2f} %, largest gap "
            f"{float(row['max_gap_m']):.1f} m, {float(row['gap_out_of_bounds_s']):.1f} s out of "
            f"bounds, {row['collisions']} collisions, {float(row['seconds']):.0f} s"
            + (
                f" (starts: {', '.join(by_start[str(row['drive'])])})"
                if len(every_start) > 1
                else ""
            )
        )
    if rows:
        from sim.rl.scores import is_stop_and_go

        saving = {str(row["drive"]): float(row["fuel_saving_pct"]) for row in rows}
        groups = {
            "shockwave": [d.name for d in drives if d.kind == "shockwave"],
            "stop-and-go": [d.name for d in drives if is_stop_and_go(d)],
            "freeflow": [d.name for d in drives if d.kind == "freeflow"],
        }
        for group, members in groups.items():
            values = [saving[name] for name in members if name in saving]
            if values:
                console.print(
                    f"{group} ({len(values)} drives): mean {sum(values) / len(values):+.2f} % "
                    f"[{min(values):+.2f}, {max(values):+.2f}]"
                )
        console.print(f"wrote {out_dir / 'optimum.csv'}")
    if refused:
        raise click.ClickException(
            f"no bound for {len(refused)} of {len(drives)} drives: " + "; ".join(refused)
        )
