"""`smoothfleet sim time-space`: the all-human platoon beside the recommended pair on one drive."""

from __future__ import annotations

from pathlib import Path

import click

from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from sim.drives import DriveError, load_drive
from sim.evaluate import BASELINE, Evaluation, RunResult, run_case
from sim.platoon import PlatoonRun
from sim.recommended import RECOMMENDED_CONTROLLER
from sim.report import percent_text, write_time_space
from sim.scenarios import Case
from smoothfleet.cli.common import output_file, write_output_with
from smoothfleet.cli.sim.shared import console, default_folder


@click.command("time-space")
@click.option(
    "--drive",
    "drive_path",
    type=click.Path(path_type=Path, exists=True, dir_okay=False),
    default=lambda: default_folder("trajectories/2021-03-15-12-46-38_masterArray_0_8314.csv"),
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
    _check_figure_format(output)
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


def _check_figure_format(output: Path) -> None:
    """A BadParameter unless matplotlib writes the format `output`'s suffix names: without one
    (`-o ts`), or with one it does not know, the whole simulation ran before the save failed
    with "Format 'partial' is not supported"."""
    from matplotlib.backend_bases import FigureCanvasBase

    formats = FigureCanvasBase.get_supported_filetypes()
    if output.suffix.lower().lstrip(".") not in formats:
        known = ", ".join(f".{name}" for name in sorted(formats))
        raise click.BadParameter(
            f"{output}: name the figure's format by its suffix, one of {known}",
            param_hint="--output",
        )
