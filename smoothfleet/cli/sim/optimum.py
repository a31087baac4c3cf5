"""`smoothfleet sim optimum`: each drive's fuel-optimal AV trajectory, the bound of every
controller's saving."""

from __future__ import annotations

from pathlib import Path

import click

from smoothfleet.cli.common import FiniteFloatRange, output_folder, write_output_with
from smoothfleet.cli.sim.shared import console, drives_option, progress_bar, read_drives


@click.command("optimum")
@drives_option("Folder of real drive CSVs (10 Hz)")
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
    drives = read_drives(drives_dir)
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
                # the key holds the drive's speeds and the humans: the row was computed on them
                solved.append({**row, "drive_fingerprint": drive.fingerprint, "humans": humans})
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
