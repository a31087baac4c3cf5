"""`smoothfleet sim select`: choose the deployment pair by cross-validation that keeps whole dates
apart, and report only the folds each choice was not made on."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import click
from rich.progress import TaskID
from rich.table import Table

from planner.params import InvalidParams
from planner.pipeline import parse_params
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.evaluate import BASELINE, ControllerVariant, PolicyDatesUnknown, default_workers, evaluate
from sim.folds import drive_date
from sim.recommended import registered_variants
from sim.report import percent_text, write_rows
from sim.selection import (
    candidate_summary,
    check_every_fold_can_choose,
    choose,
    cross_validate,
    held_out_summary,
)
from smoothfleet.cli.common import FiniteFloatRange, output_folder, write_output_with
from smoothfleet.cli.sim.shared import (
    chosen_cases,
    console,
    controller_variants,
    drives_option,
    progress_bar,
    read_drives,
)

# Candidates `sim select` adds to the registered pairs: the gains the evaluation found to matter.
SELECTION_VARIANTS = (
    'microaccel:accel:{"k": 0.2}',
    'microaccel:accel:{"k": 0.05}',
    'microaccel_acc:acc:{"base": {"k": 0.05}}',
)


@click.command("select")
@drives_option("Folder of real drive CSVs (10 Hz)")
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
        controller_variants(controllers)
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
    drives = read_drives(drives_dir)
    cases = chosen_cases(["shockwave", "freeflow"], drives)
    try:
        check_every_fold_can_choose(
            ((drive_date(case.drive), case.scenario) for case in cases),
            folds,
            set().union(*fitted_dates.values()),
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
            parse_params(params)
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
