"""What the `smoothfleet sim` commands share: the console and progress bar, and reading the
drives and controller variants a command is given, each mistake named before anything runs."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from sim.drives import (
    FREEFLOW_MIN_SPEED_MPS,
    FREEFLOW_PERCENTILE,
    MAX_FILLED_GAP_S,
    MAX_LEADER_ACCEL_MPS2,
    STEP_S,
    Drive,
    DriveError,
    load_drives,
    shared_data_dir,
)
from sim.evaluate import ControllerVariant
from sim.recommended import registered_variants
from sim.recorded import RecordedDrive, load_recorded_drives
from sim.scenarios import Case, scenario_cases
from vehicle_agent.controllers.registry import build_controller

# Wide enough for the evaluation table when the output is a file or a pipe.
console = Console(width=max(Console().width, 160))


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


def controller_variants(texts: tuple[str, ...]) -> list[ControllerVariant]:
    """The variants named, each built once as the agent builds it (its parameters checked, its
    policy file read), so a mistake is named before any drive is simulated."""
    try:
        variants = [ControllerVariant.parse(text) for text in texts]
        for variant in variants:
            build_controller(variant.controller, variant.actuation, variant.params)
    except ValueError as error:  # ControllerConfigError and PolicyFileError among them
        raise click.BadParameter(str(error), param_hint="--controller") from None
    return variants or registered_variants()


def read_drives(drives_dir: Path) -> list[Drive]:
    """The folder's drives, or a ClickException naming the file and row that cannot be
    replayed; a drive whose missing samples were filled is named, with how much was filled."""
    try:
        drives = load_drives(drives_dir)
    except DriveError as error:
        raise click.ClickException(str(error)) from None
    say_filled(drives)
    return drives


def read_recorded_drives(inrix_dir: Path) -> list[RecordedDrive]:
    """`read_drives` for the drives recorded with their INRIX minutes."""
    try:
        recorded = load_recorded_drives(inrix_dir)
    except DriveError as error:
        raise click.ClickException(str(error)) from None
    say_filled([one.drive for one in recorded])
    return recorded


def say_filled(drives: Sequence[Drive]) -> None:
    """Name each drive the loader filled, and each whose speed jumps faster than a car can."""
    for drive in drives:
        if drive.filled_s > 0.0:
            console.print(
                f"{drive.name}: {drive.filled_s:.1f} s between samples off the "
                f"{STEP_S:g} s grid, filled by linear interpolation (gaps up to "
                f"{MAX_FILLED_GAP_S:g} s are)"
            )
        glitches, first_s = drive.glitches
        if glitches:
            console.print(
                f"{drive.name}: the leader's speed changes faster than "
                f"{MAX_LEADER_ACCEL_MPS2:g} m/s^2 at {glitches} step(s), the first {first_s:.1f} s "
                "in, most likely a sensor's glitch; replayed as recorded, so the platoon brakes "
                "for it (its takeovers and collisions may be the glitch's)"
            )


def chosen_cases(
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


def default_folder(name: str) -> Path | None:
    try:
        return shared_data_dir() / name
    except DriveError:
        return None


def drives_option(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """`--drives`: the folder of real drives a command reads, the shared data's by default."""
    return click.option(
        "--drives",
        "drives_dir",
        type=click.Path(path_type=Path),
        default=lambda: default_folder("trajectories"),
        help=f"{what} [default: shared/data/trajectories beside the checkout, or "
        "$SMOOTHFLEET_SHARED_DATA].",
    )
