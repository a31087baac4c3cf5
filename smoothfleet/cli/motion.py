"""`smoothfleet motion import | generate | edie | plot`: I-24 MOTION analytics (docs/analytics.md).

The MOTION store is Parquet under SMOOTHFLEET_MOTION_DIR (default DATA_DIR/motion), read with
DuckDB; `plot` also reads the fleet's pings from the warehouse.
"""

from __future__ import annotations

from datetime import UTC, date, datetime
from pathlib import Path
from zoneinfo import ZoneInfo

import click
from rich.progress import (
    BarColumn,
    DownloadColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeRemainingColumn,
    TransferSpeedColumn,
)

from app.motion.documents import MotionFileError
from app.motion.edie import H_T_S, H_X_M, EdieWindow, EdieWindowError, edie_field
from app.motion.importer import ImportReport, import_motion_file
from app.motion.store import MotionStoreEmpty, motion_store
from contract.units import FEET_PER_MILE
from sim.drives import DriveError, load_drive, shared_data_dir
from sim.motion.frame import DEFAULT_ANCHOR_X_FT, DEFAULT_ANCHOR_X_M, MotionFrame
from sim.motion.traffic import MotionRunConfig, boundary_speeds, simulate_motion_run
from sim.motion.write import write_motion_json
from smoothfleet.cli.common import (
    CliError,
    FiniteFloatRange,
    console,
    database,
    output_file,
    replaced_on_success,
    settings,
    write_output,
)

# Real stop-and-go drives whose speeds set the traffic downstream of a generated hour.
DEFAULT_BOUNDARY_DRIVES = (
    "2021-03-08-22-35-14_masterArray_0_5373.csv",
    "2021-03-09-13-35-04_masterArray_0_4633.csv",
)
# The testbed's section on the seed corridor under the default frame: mileposts 62.7 to 58.7.
TESTBED_START_X_M = float(MotionFrame().x_m(62.7 * FEET_PER_MILE))
REASONS_SHOWN = 20


@click.group("motion")
def motion() -> None:
    """I-24 MOTION trajectories: import, Edie fields, the bulk-fuel figure."""


@motion.command("import")
@click.argument("files", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--store", type=click.Path(path_type=Path), help="Default: DATA_DIR/motion.")
@click.option(
    "--anchor-x-ft",
    type=FiniteFloatRange(),
    default=DEFAULT_ANCHOR_X_FT,
    show_default=True,
    help="MOTION x (ft) of the tie point.",
)
@click.option(
    "--anchor-x-m",
    type=FiniteFloatRange(),
    default=DEFAULT_ANCHOR_X_M,
    show_default=True,
    help="Corridor x_m of the tie point.",
)
@click.option(
    "--direction",
    type=click.Choice(["-1", "1"]),
    default="-1",
    show_default=True,
    help="The corridor's MOTION direction (-1 westbound).",
)
def motion_import(
    files: tuple[Path, ...],
    store: Path | None,
    anchor_x_ft: float,
    anchor_x_m: float,
    direction: str,
) -> None:
    """Import MOTION JSON FILES (any size, streamed); re-importing a file adds nothing."""
    target = store or motion_store(settings())
    frame = MotionFrame(direction=int(direction), anchor_x_ft=anchor_x_ft, anchor_x_m=anchor_x_m)
    failed = False
    for path in files:
        if not path.is_file():
            raise CliError(f"{path}: no such file")
        with Progress(
            TextColumn(path.name),
            BarColumn(),
            DownloadColumn(),
            TransferSpeedColumn(),
            TimeRemainingColumn(),
            console=console,
            transient=True,
        ) as progress:
            task = progress.add_task("import", total=path.stat().st_size)

            def advance(done: int, task: TaskID = task, progress: Progress = progress) -> None:
                progress.update(task, completed=done)

            try:
                report = import_motion_file(path, target, frame, advance)
            except MotionFileError as error:
                raise CliError(f"{path}: {error}") from None
        _print_report(report)
        failed = failed or report.file_error is not None
    if failed:
        raise CliError("a file's JSON broke off; the documents before the break were imported")


def _print_report(report: ImportReport) -> None:
    if report.already_imported:
        console.print(
            f"{report.path}: already imported (sha256 {report.sha256[:16]}), nothing added"
        )
        return
    console.print(
        f"{report.path}: {report.documents} trajectories, {report.points:,} points imported in "
        f"{report.seconds:.1f} s ({report.points_per_s:,.0f} points/s); "
        f"{report.duplicates} already in the store, {report.other_direction} of the other "
        f"direction, {len(report.bad)} bad"
    )
    for bad in report.bad[:REASONS_SHOWN]:
        console.print(f"  document {bad.index} (byte {bad.offset}): {bad.reason}")
    if len(report.bad) > REASONS_SHOWN:
        console.print(f"  ... and {len(report.bad) - REASONS_SHOWN} more (imports/*.json)")
    if report.file_error:
        console.print(f"  the file's JSON breaks at {report.file_error}")


@motion.command("generate")
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path))
@click.option("--start", "start_text", help="UTC start, ISO 8601 (default: this hour).")
@click.option(
    "--duration",
    "duration_s",
    type=FiniteFloatRange(min=0, min_open=True),
    default=3600.0,
    show_default=True,
    help="Seconds.",
)
@click.option("--lanes", type=click.IntRange(min=1), default=4, show_default=True)
@click.option(
    "--demand",
    "demand_vph",
    type=FiniteFloatRange(min=0, min_open=True),
    default=1500.0,
    show_default=True,
    help="Vehicles per hour and lane entering upstream.",
)
@click.option("--fleet-share", type=FiniteFloatRange(0.0, 1.0), default=0.02, show_default=True)
@click.option(
    "--seed",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Of the random demand and vehicle mix (numpy takes no negative seed).",
)
@click.option(
    "--drive",
    "drives",
    multiple=True,
    type=click.Path(path_type=Path),
    help="Real drive CSV(s) setting the downstream speed (default: two stop-and-go "
    "drives of ../shared/data/trajectories).",
)
def motion_generate(
    output: Path,
    start_text: str | None,
    duration_s: float,
    lanes: int,
    demand_vph: float,
    fleet_share: float,
    seed: int,
    drives: tuple[Path, ...],
) -> None:
    """Simulate every vehicle of the testbed's section and write it as MOTION JSON."""
    start = (
        _moment(start_text)
        if start_text
        else datetime.now(UTC).replace(minute=0, second=0, microsecond=0)
    )
    try:
        paths = drives or tuple(
            shared_data_dir() / "trajectories" / name for name in DEFAULT_BOUNDARY_DRIVES
        )
        boundary = boundary_speeds([load_drive(path) for path in paths], duration_s)
        config = MotionRunConfig(
            start_unix_s=start.timestamp(),
            duration_s=duration_s,
            section_start_m=TESTBED_START_X_M,
            lanes=lanes,
            demand_veh_per_h_per_lane=demand_vph,
            fleet_share=fleet_share,
            seed=seed,
        )
    except (DriveError, ValueError) as error:
        raise CliError(str(error)) from None
    output_file(output, "--output")
    with (
        console.status(f"simulating {duration_s:g} s of {lanes} lanes"),
        replaced_on_success(output) as partial,
    ):
        documents, points = write_motion_json(
            partial, simulate_motion_run(config, boundary), MotionFrame(), seed
        )
    console.print(f"{output}: {documents} trajectories, {points:,} points from {start.isoformat()}")


@motion.command("edie")
@click.option("--since", required=True, help="ISO 8601 (UTC unless a zone is given).")
@click.option("--until", required=True)
@click.option("--from-m", "x_from_m", type=FiniteFloatRange(), default=0.0, show_default=True)
@click.option("--to-m", "x_to_m", type=FiniteFloatRange(), default=15_000.0, show_default=True)
@click.option(
    "--h-t",
    "h_t_s",
    type=FiniteFloatRange(),
    default=H_T_S,
    show_default=True,
    help="Box duration, s.",
)
@click.option(
    "--h-x",
    "h_x_m",
    type=FiniteFloatRange(),
    default=H_X_M,
    show_default=True,
    help="Box length, m.",
)
@click.option("--lane", type=int, help="One lane (default: all).")
@click.option("-o", "--output", type=click.Path(path_type=Path), help="CSV (default: stdout).")
@click.option("--store", type=click.Path(path_type=Path))
def motion_edie(
    since: str,
    until: str,
    x_from_m: float,
    x_to_m: float,
    h_t_s: float,
    h_x_m: float,
    lane: int | None,
    output: Path | None,
    store: Path | None,
) -> None:
    """Edie's fields (rho, q, f, u, phi, psi, counts) per box, as CSV."""
    try:
        window = EdieWindow(_moment(since), _moment(until), x_from_m, x_to_m, h_t_s, h_x_m, lane)
    except EdieWindowError as error:
        raise CliError(str(error)) from None
    if output is not None:
        output_file(output, "--output")
    field = edie_field(store or motion_store(settings()), window)
    text = field.to_csv(index=False, date_format="%Y-%m-%dT%H:%M:%SZ")
    if output is None:
        click.echo(text, nl=False)
    else:
        write_output(output, text)
        console.print(f"{output}: {len(field)} boxes")


@motion.command("plot")
@click.option("--date", "day_text", required=True, help="UTC day, YYYY-MM-DD.")
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path))
@click.option("--corridor", "corridor_id", default="I-24-WB", show_default=True)
@click.option("--store", type=click.Path(path_type=Path))
def motion_plot(day_text: str, output: Path, corridor_id: str, store: Path | None) -> None:
    """The paper's psi(t, x) heatmap (and u) with the fleet's trajectories, as a PNG."""
    # matplotlib and SQLAlchemy: imported by this command alone
    from app.core.db import make_sync_engine
    from app.motion.figure import day_figure

    try:
        day = date.fromisoformat(day_text)
    except ValueError:
        raise CliError(f"--date {day_text!r} is not YYYY-MM-DD") from None
    output_file(output, "--output")
    current = settings()
    with database(current) as url:
        engine = make_sync_engine(url)
        try:
            with engine.connect() as connection:
                png = day_figure(
                    store or motion_store(current),
                    connection,
                    day,
                    corridor_id,
                    ZoneInfo(current.dashboard_timezone),
                )
        except MotionStoreEmpty as error:
            raise CliError(str(error)) from None
        finally:
            engine.dispose()
    write_output(output, png)
    console.print(f"{output}: figure of {day.isoformat()}")


def _moment(value: str) -> datetime:
    try:
        moment = datetime.fromisoformat(value)
    except ValueError:
        raise CliError(f"{value!r} is not an ISO 8601 date or time") from None
    return moment if moment.tzinfo else moment.replace(tzinfo=UTC)
