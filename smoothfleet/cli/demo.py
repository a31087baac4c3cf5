"""`smoothfleet demo`: the whole loop on one machine.

Given a migrated and seeded database (the CLI starts the embedded PostgreSQL), the demo
- issues a bearer token to every active roster vehicle and one to the INRIX feed;
- starts the server (`smoothfleet serve`: API, dashboard and the planner schedule) as its own
  process, so its CPU share can be read apart from the fleet's;
- posts a simulated INRIX feed to POST /api/v1/feeds/inrix every minute (the last 15 minutes at
  once when it starts, as a feed that was already running would have), from the traffic of
  `sim.fleet.traffic`: a real stop-and-go drive's waves looping over the corridor;
- runs the fleet in worker processes (`sim.fleet.worker`): every vehicle the real agent on its
  own virtual CAN bus with a car emulator, talking HTTP with its own token;
- stops on Ctrl-C or after `duration_s`, and prints what happened: pings stored and from how
  many vehicles, plans published, engagement share, the fleet's fuel economy and speed, and
  the CPU share of the server and of the fleet.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any
from zoneinfo import ZoneInfo

import click
import httpx
from sqlalchemy import Engine, select, text

from app.core.config import Settings
from app.core.db import make_sync_engine, redact, session_scope
from app.core.security import issue_token, revoke_tokens
from app.models.dimensions import InrixSegment, Vehicle
from app.users.service import new_password, save_user
from contract.units import METRES_PER_MILE, MPH_PER_MPS
from sim.drives import Drive, DriveError, load_drive, shared_data_dir
from sim.energy import GALLONS_PER_GRAM_GASOLINE
from sim.fleet.traffic import CorridorTraffic, Segment, synthetic_waves
from sim.fleet.worker import VehicleSpec, WorkerSpec
from smoothfleet.cli.common import CliError, console, database, fleet_options
from smoothfleet.cli.demo_status import StatusMonitor
from smoothfleet.cli.serve import ensure_port_free, with_overrides

CORRIDOR = "I-24-WB"
# The strongest stop-and-go drive of the shared data, 300 s in: waves from the first minute.
TRAFFIC_DRIVE_FILE = "trajectories/2021-04-05-21-39-05_masterArray_1_9955.csv"


def traffic_drive_path() -> Path:
    """Where the demo's traffic drive is: in the shared data `sim.drives.shared_data_dir` finds
    ($SMOOTHFLEET_SHARED_DATA, or `shared/data` beside the checkout or the working directory),
    as every other command finds it. It was looked for beside this file alone, so a demo
    installed other than in editable mode ran synthetic waves whatever the setting said. Where
    no shared data is found, the relative path, which the demo reports missing before it falls
    back to synthetic waves."""
    try:
        return shared_data_dir() / TRAFFIC_DRIVE_FILE
    except DriveError:
        return Path("shared/data") / TRAFFIC_DRIVE_FILE


TRAFFIC_DRIVE = traffic_drive_path()
TRAFFIC_OFFSET_S = 300.0
FEED_PERIOD_S = 60.0
FEED_BACKFILL_MINUTES = 15
FLEET_WORKERS = 2
# Cars start this far inside the corridor's ends (m).
START_MARGIN_M = 300.0
READY_TIMEOUT_S = 90.0
STOP_TIMEOUT_S = 90.0
# The emulated cars send each watched message at most once per 0.1 s control step (sim.emulator:
# 40 frames/s for a 2023 Rogue, whose schedule is 80/s; 60 of a RAV4's 180/s and 50 of a 2018-20
# Rogue's 150/s, the least share, a third),
# so the demo's server expects CAN traffic at half of that (amber below 1/6 of the schedule) and
# keeps red where the agent's inputs go stale.
DEMO_SERVER_SETTINGS = {"SMOOTHFLEET_READINESS_CAN_SHARE": "[0.167, 0.1]"}

# A fleet worker process and the file its summary goes to.
WorkerProcess = tuple[subprocess.Popen[bytes], Path]


@dataclass(frozen=True)
class DemoSummary:
    """What a demo run did."""

    duration_s: float
    vehicles: int
    pings_stored: int
    vehicles_pinging: int
    plans_published: int
    inrix_snapshots: int
    engaged_share: float
    pings_engaged_share: float
    fuel_economy_mpg: float
    mean_speed_mps: float
    server_cpu_share: float | None
    fleet_cpu_share: float | None
    late_control_steps: float
    # Seconds between a car's control steps, and the CPU one step of the whole worker takes.
    mean_step_interval_s: float
    step_cpu_s: float
    # Cars the status line saw cleared, and verdict changes after a car's first clearance.
    cars_cleared: int = 0
    verdict_flips: int = 0

    def lines(self) -> list[str]:
        """The closing summary, one fact per line."""
        cpu = (
            f"CPU (share of one core): server {_share(self.server_cpu_share)}, "
            f"fleet {_share(self.fleet_cpu_share)}"
        )
        return [
            f"ran {self.duration_s:.0f} s with {self.vehicles} vehicles",
            f"pings stored: {self.pings_stored} from {self.vehicles_pinging} vehicles",
            f"plans published: {self.plans_published} (INRIX snapshots posted and stored: "
            f"{self.inrix_snapshots})",
            f"engaged on the plan: {100 * self.engaged_share:.0f} % of vehicle-time "
            f"({100 * self.pings_engaged_share:.0f} % of stored pings)",
            f"fleet so far: {self.fuel_economy_mpg:.1f} mpg (RAV4 fuel model), mean speed "
            f"{self.mean_speed_mps * MPH_PER_MPS:.1f} mph",
            f"clearance: {self.cars_cleared} cars cleared, {self.verdict_flips} verdict changes "
            "after a car's first clearance (status line every 5 s)",
            cpu,
            f"control steps: every {self.mean_step_interval_s:.2f} s on average (goal 0.10 s, "
            f"{100 * self.late_control_steps:.0f} % late); one step of a worker's cars takes "
            f"{1000 * self.step_cpu_s:.0f} ms of CPU",
        ]


def _share(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.0f} %"


def process_cpu_s(pid: int) -> float | None:
    """User + system CPU seconds of a running process (Linux /proc), None elsewhere."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks


def fleet_specs(
    engine: Engine,
    settings: Settings,
    base_url: str,
    run_dir: Path,
    epoch: float,
    drive_path: Path | None,
    vehicles: int,
    workers: int,
) -> tuple[list[WorkerSpec], list[str], list[Segment]]:
    """Tokens for the fleet, the feed and the status line (in that order after the fleet's),
    and the workers' specs (cars spread per lane)."""
    with session_scope(engine) as session:
        roster = [
            vehicle
            for vehicle in session.scalars(select(Vehicle).order_by(Vehicle.vehicle_id))
            if vehicle.is_active and not vehicle.is_in_maintenance
        ][:vehicles]
        segments = [
            Segment(row.xd_code, row.start_x_m, row.end_x_m)
            for row in session.scalars(
                select(InrixSegment)
                .where(InrixSegment.corridor_id == CORRIDOR)
                .order_by(InrixSegment.start_x_m)
            )
        ]
        length = max(segment.end_x_m for segment in segments)
        by_lane: dict[int, list[Vehicle]] = {}
        for vehicle in roster:
            by_lane.setdefault(vehicle.assigned_lane, []).append(vehicle)
        specs: list[VehicleSpec] = []
        for lane, lane_vehicles in sorted(by_lane.items()):
            spacing = (length - 2 * START_MARGIN_M) / len(lane_vehicles)
            for order, vehicle in enumerate(lane_vehicles):
                specs.append(
                    VehicleSpec(
                        vehicle_id=vehicle.vehicle_id,
                        make=vehicle.make,
                        model=vehicle.model,
                        year=vehicle.year,
                        lane=lane,
                        token=issue_token(
                            session, "vehicle", vehicle_id=vehicle.vehicle_id, name="demo"
                        ),
                        position_m=START_MARGIN_M + (order + 0.5 * (lane % 2)) * spacing,
                    )
                )
        feed_token = issue_token(session, "feed", name="demo INRIX feed")
        viewer_token = issue_token(session, "viewer", name="demo status line")
    worker_specs = [
        WorkerSpec(
            server_url=base_url,
            corridor_id=CORRIDOR,
            epoch_unix_s=epoch,
            drive_path=str(drive_path) if drive_path is not None else None,
            traffic_offset_s=TRAFFIC_OFFSET_S,
            spool_dir=str(run_dir / "spools"),
            dbc_cache=str(settings.data_dir / "dbc"),
            vehicles=specs[part::workers],
            progress_path=str(run_dir / f"worker-{part}.progress.json"),
        )
        for part in range(workers)
        if specs[part::workers]
    ]
    return worker_specs, [feed_token, viewer_token], segments


class InrixFeed:
    """Posts the simulated INRIX every minute to the real feed endpoint."""

    def __init__(
        self,
        base_url: str,
        token: str,
        traffic: CorridorTraffic,
        segments: Sequence[Segment],
        epoch: float,
    ) -> None:
        self.http = httpx.Client(
            base_url=base_url, headers={"Authorization": f"Bearer {token}"}, timeout=10.0
        )
        self.traffic = traffic
        self.segments = list(segments)
        self.epoch = epoch
        self.stop = threading.Event()
        self.posted = 0
        self.errors: list[str] = []

    def post(self, demo_time_s: float) -> None:
        """One snapshot: the minute that ended INRIX's latency before `demo_time_s`."""
        wall = datetime.fromtimestamp(self.epoch + demo_time_s, UTC)
        body = self.traffic.inrix_response(demo_time_s, wall, self.segments)
        try:
            response = self.http.post("/api/v1/feeds/inrix", json=body)
        except httpx.HTTPError as error:
            self.errors.append(f"{type(error).__name__}: {error}")
            return
        if response.status_code == 200:
            self.posted += 1
        else:
            self.errors.append(f"HTTP {response.status_code}: {response.text[:200]}")

    def backfill(self) -> None:
        """The last minutes at once, as a feed that was already running would have posted."""
        now = time.time() - self.epoch
        for minutes_ago in range(FEED_BACKFILL_MINUTES, 0, -1):
            self.post(now - minutes_ago * FEED_PERIOD_S)

    def run(self) -> None:
        """One snapshot a minute until stopped."""
        while not self.stop.is_set():
            self.post(time.time() - self.epoch)
            self.stop.wait(FEED_PERIOD_S)
        self.http.close()


class DemoError(RuntimeError):
    """The demo could not run (the server or a fleet worker failed); the message says which."""


def wait_ready(base_url: str, server: subprocess.Popen[bytes], timeout_s: float) -> None:
    """Until /readyz answers 200; fails if the server process ends first."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise DemoError(f"the server exited with code {server.returncode}")
        try:
            if httpx.get(f"{base_url}/readyz", timeout=2.0).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise DemoError(f"the server at {base_url} was not ready after {timeout_s:.0f} s")


def run_demo(
    url: str,
    settings: Settings,
    *,
    duration_s: float | None,
    vehicles: int = 100,
    drive_path: Path | None = TRAFFIC_DRIVE,
    say: Callable[[str], None] = print,
) -> DemoSummary:
    """Server, feed and fleet until Ctrl-C or `duration_s`; returns the summary."""
    run_dir = new_run_dir(settings)
    base = f"http://{settings.host}:{settings.port}"
    env = {**os.environ, **DEMO_SERVER_SETTINGS, "SMOOTHFLEET_DATABASE_URL": url}
    with (run_dir / "server.log").open("wb") as server_log:
        server = subprocess.Popen(
            [
                *smoothfleet_command(),
                "serve",
                "--no-migrate",
                "--host",
                settings.host,
                "--port",
                str(settings.port),
            ],
            env=env,
            stdout=server_log,
            stderr=subprocess.STDOUT,
            # Ctrl-C reaches only the demo, which then stops the fleet before the server.
            start_new_session=True,
        )
    try:
        wait_ready(base, server, READY_TIMEOUT_S)

        def first_plan() -> None:
            # A plan now rather than at the schedule's next minute (the schedule's first run
            # came before any INRIX had arrived).
            with (run_dir / "planner-once.log").open("wb") as planner_log:
                subprocess.run(
                    [*smoothfleet_command(), "planner", "once"],
                    env=env,
                    stdout=planner_log,
                    stderr=subprocess.STDOUT,
                    check=False,
                    start_new_session=True,
                )

        return run_fleet(
            url,
            settings,
            base,
            run_dir=run_dir,
            duration_s=duration_s,
            vehicles=vehicles,
            drive_path=drive_path,
            say=say,
            server_pid=server.pid,
            after_backfill=first_plan,
        )
    finally:
        server.send_signal(signal.SIGTERM)
        try:
            server.wait(timeout=30)
        except subprocess.TimeoutExpired:
            server.kill()


def new_run_dir(settings: Settings) -> Path:
    """Where a run keeps its logs, the workers' specs and the cars' spools."""
    run_dir = settings.data_dir / "demo" / datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def run_fleet(
    url: str,
    settings: Settings,
    base_url: str,
    *,
    run_dir: Path,
    duration_s: float | None,
    vehicles: int = 100,
    drive_path: Path | None = TRAFFIC_DRIVE,
    say: Callable[[str], None] = print,
    server_pid: int | None = None,
    after_backfill: Callable[[], None] | None = None,
) -> DemoSummary:
    """The simulated INRIX feed and fleet against the server at `base_url` (tokens issued in
    the database at `url`), until Ctrl-C or `duration_s`; returns the summary."""
    if drive_path is not None and not drive_path.is_file():
        say(
            f"no {drive_path}: the traffic is synthetic stop-and-go waves instead (the shared "
            "data is found at ../shared beside the checkout, or at SMOOTHFLEET_SHARED_DATA)"
        )
        drive_path = None
    engine = make_sync_engine(url)
    epoch = time.time()
    started = datetime.fromtimestamp(epoch, UTC)
    specs, (feed_token, viewer_token), segments = fleet_specs(
        engine, settings, base_url, run_dir, epoch, drive_path, vehicles, FLEET_WORKERS
    )
    monitor = StatusMonitor(
        base_url,
        viewer_token,
        engine,
        [Path(spec.progress_path) for spec in specs if spec.progress_path is not None],
        say,
        ZoneInfo(settings.dashboard_timezone),
    )
    monitor_thread = threading.Thread(target=monitor.run, name="status-line", daemon=True)
    workers: list[WorkerProcess] = []
    traffic = CorridorTraffic(traffic_drive(drive_path), start_offset_s=TRAFFIC_OFFSET_S)
    feed = InrixFeed(base_url, feed_token, traffic, segments, epoch)
    feed_thread = threading.Thread(target=feed.run, name="inrix-feed", daemon=True)
    try:
        feed.backfill()
        if after_backfill is not None:
            after_backfill()
        feed_thread.start()
        workers = [start_worker(run_dir, index, spec) for index, spec in enumerate(specs)]
        say(
            f"fleet: {sum(len(spec.vehicles) for spec in specs)} vehicles in {len(workers)} "
            f"processes; logs in {run_dir}"
        )
        monitor_thread.start()
        measured_from = time.monotonic()
        server_pids = [] if server_pid is None else [server_pid]
        pids = server_pids + [process.pid for process, _ in workers]
        cpu_start = {pid: process_cpu_s(pid) for pid in pids}
        deadline = math.inf if duration_s is None else measured_from + duration_s
        try:
            while time.monotonic() < deadline:
                for process, _ in workers:
                    if process.poll() is not None:
                        raise DemoError(
                            f"a fleet worker exited (code {process.returncode}); see {run_dir}"
                        )
                time.sleep(min(1.0, max(0.0, deadline - time.monotonic())))
        except (KeyboardInterrupt, SystemExit):  # Ctrl-C, or SIGTERM through the CLI's handler
            say("interrupted")
        elapsed = time.monotonic() - measured_from
        cpu_end = {pid: process_cpu_s(pid) for pid in pids}
        monitor.stop.set()
        monitor_thread.join(timeout=15)
        say("stopping: the agents hand their cars back and upload their spools ...")
        summaries = stop_workers(workers)
        feed.stop.set()
        feed_thread.join(timeout=15)
        if feed.errors:
            say(f"INRIX feed: {len(feed.errors)} failed posts, last: {feed.errors[-1]}")
        return summarise(
            engine,
            started,
            elapsed,
            summaries,
            cpu_share(server_pids, cpu_start, cpu_end, elapsed) if server_pids else None,
            cpu_share([p.pid for p, _ in workers], cpu_start, cpu_end, elapsed),
            len(monitor.tracker.cleared_once),
            monitor.tracker.flips,
        )
    finally:
        for process, _ in workers:
            if process.poll() is None:
                process.kill()
        feed.stop.set()
        monitor.stop.set()
        # The run's tokens end with it: a simulated car's token left valid is a live credential
        # in a spec file on disk.
        revoke_run_tokens(engine, specs, [feed_token, viewer_token])
        engine.dispose()


def revoke_run_tokens(engine: Engine, specs: Sequence[WorkerSpec], others: Sequence[str]) -> None:
    """Revoke every token a fleet run issued (its cars', its INRIX feed's, its status line's)."""
    tokens = [vehicle.token for spec in specs for vehicle in spec.vehicles] + list(others)
    with session_scope(engine) as session:
        for token in tokens:
            revoke_tokens(session, token=token)


def start_worker(run_dir: Path, index: int, spec: WorkerSpec) -> WorkerProcess:
    """A fleet worker process; its spec (with the cars' tokens) is readable by the user only."""
    spec_path = run_dir / f"worker-{index}.json"
    spec_path.touch(mode=0o600)
    spec_path.write_text(spec.model_dump_json())
    summary_path = run_dir / f"worker-{index}.summary.json"
    with (run_dir / f"worker-{index}.log").open("wb") as log:
        process = subprocess.Popen(
            [sys.executable, "-m", "sim.fleet.worker", str(spec_path), str(summary_path)],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    return process, summary_path


def stop_workers(workers: Sequence[WorkerProcess]) -> list[dict[str, Any]]:
    """SIGTERM every worker, wait for it, and read its summary."""
    for process, _ in workers:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    summaries = []
    for process, summary_path in workers:
        try:
            process.wait(timeout=STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            continue
        if summary_path.exists():
            summaries.append(json.loads(summary_path.read_text()))
    return summaries


def traffic_drive(drive_path: Path | None) -> Drive:
    """The drive whose waves make the demo's traffic (synthetic waves without the data)."""
    return load_drive(drive_path) if drive_path is not None else synthetic_waves()


def cpu_share(
    pids: Sequence[int],
    start: dict[int, float | None],
    end: dict[int, float | None],
    elapsed: float,
) -> float | None:
    """CPU seconds the processes used per second of `elapsed` (1.0 = one core)."""
    used = 0.0
    for pid in pids:
        before, after = start.get(pid), end.get(pid)
        if before is None or after is None or elapsed <= 0:
            return None
        used += after - before
    return used / elapsed


def summarise(
    engine: Engine,
    started: datetime,
    elapsed: float,
    workers: list[dict[str, Any]],
    server_cpu: float | None,
    fleet_cpu: float | None,
    cars_cleared: int = 0,
    verdict_flips: int = 0,
) -> DemoSummary:
    """The closing summary from the database and the workers' own counts."""
    with engine.connect() as connection:
        pings, vehicles_pinging, engaged = connection.execute(
            text(
                "SELECT count(*), count(DISTINCT vehicle_id), "
                "coalesce(avg(is_controller_engaged::int), 0) "
                "FROM fact_vehicle_ping WHERE ts >= :started"
            ),
            {"started": started},
        ).one()
        plans = connection.execute(
            text(
                "SELECT count(*) FROM plan_run WHERE status = 'published' "
                "AND published_at >= :started"
            ),
            {"started": started},
        ).scalar_one()
        snapshots = connection.execute(
            text(
                "SELECT count(DISTINCT measured_at) FROM fact_inrix_estimate "
                "WHERE received_at >= :started"
            ),
            {"started": started},
        ).scalar_one()
    fleet = sum(w["vehicles"] for w in workers)
    steps = sum(w["control_steps"] * w["vehicles"] for w in workers)
    distance = sum(w["distance_m"] for w in workers)
    fuel = sum(w["fuel_g"] for w in workers)
    worker_steps = sum(w["control_steps"] for w in workers)
    return DemoSummary(
        duration_s=elapsed,
        vehicles=fleet,
        pings_stored=int(pings),
        vehicles_pinging=int(vehicles_pinging),
        plans_published=int(plans),
        inrix_snapshots=int(snapshots),
        engaged_share=sum(w["engaged_share"] * w["control_steps"] * w["vehicles"] for w in workers)
        / max(1, steps),
        pings_engaged_share=float(engaged),
        fuel_economy_mpg=(distance / METRES_PER_MILE) / (fuel * GALLONS_PER_GRAM_GASOLINE)
        if fuel > 0
        else 0.0,
        mean_speed_mps=distance / max(1e-9, sum(w["driving_s"] for w in workers)),
        server_cpu_share=server_cpu,
        fleet_cpu_share=fleet_cpu,
        late_control_steps=sum(w["late_steps"] for w in workers) / max(1, worker_steps),
        mean_step_interval_s=sum(w["control_wall_s"] for w in workers) / max(1, worker_steps),
        step_cpu_s=sum(w["control_cpu_s"] for w in workers) / max(1, worker_steps),
        cars_cleared=cars_cleared,
        verdict_flips=verdict_flips,
    )


def smoothfleet_command() -> list[str]:
    """How to run this installation's `smoothfleet`."""
    script = Path(sys.executable).parent / "smoothfleet"
    return [str(script)] if script.exists() else [sys.executable, "-m", "smoothfleet.cli"]


DEMO_ADMIN = "admin"


DEMO_DATABASE = "smoothfleet_demo"


@click.command("demo")
@click.option("--host", help="Listen address (SMOOTHFLEET_HOST).")
@click.option("--port", type=int, help="Listen port (SMOOTHFLEET_PORT).")
@click.option(
    "--keep",
    is_flag=True,
    help="Keep the previous run's demo database (maintenance flags, users, plans, pings).",
)
@click.option(
    "--rl",
    is_flag=True,
    help="Run the fleet on the committed RL policies: upload them and assign rl_acc / rl_accel "
    "by sha256 to every car (each car downloads its policy).",
)
@fleet_options
def demo(
    host: str | None,
    port: int | None,
    keep: bool,
    rl: bool,
    duration: float | None,
    vehicles: int,
) -> None:
    """Everything on one machine: embedded database, migrations, seed, API, dashboard, planner,
    a simulated INRIX feed and a simulated fleet whose cars run the real vehicle agent.

    The embedded server gets a database of the demo's own, made afresh each run unless --keep;
    with SMOOTHFLEET_DATABASE_URL set, the demo uses that database as it is."""
    current = with_overrides(host=host, port=port)
    ensure_port_free(current.host, current.port)
    if current.database_url is not None:
        console.print("SMOOTHFLEET_DATABASE_URL is set: the demo uses that database as it is")
        with database(current) as url:
            _demo_on(url, current, duration, vehicles, rl=rl)
        return
    from app.core.embedded import (
        database_url,
        drop_database,
        embedded_server,
        ensure_database,
        pgdata_dir,
    )

    with (
        one_demo_per_data_dir(current.data_dir),
        embedded_server(pgdata_dir(current.data_dir)) as server_url,
    ):
        if not keep:
            drop_database(server_url, DEMO_DATABASE)
        ensure_database(server_url, DEMO_DATABASE)
        _demo_on(database_url(server_url, DEMO_DATABASE), current, duration, vehicles, rl=rl)


@contextmanager
def one_demo_per_data_dir(data_dir: Path) -> Iterator[None]:
    """Hold the data dir's demo lock for the demo's life. A second demo on the same data dir
    (another port, another terminal) dropped the running one's database: the first went on
    failing in its server log and printed a summary of the second's pings."""
    data_dir.mkdir(parents=True, exist_ok=True)
    with (data_dir / "demo.lock").open("a+") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            lock.seek(0)
            holder = lock.read().strip() or "unknown"
            raise CliError(
                f"demo: a demo is already running on {data_dir} (pid {holder}): stop it, or "
                "give this one another SMOOTHFLEET_DATA_DIR"
            ) from None
        lock.truncate(0)
        lock.write(str(os.getpid()))
        lock.flush()
        yield


def _say_whole(line: str) -> None:
    """One line of the demo's output, never wrapped at the terminal's width (a status line is
    read, and grepped from a log, as one line)."""
    console.print(line, soft_wrap=True)


def _demo_on(
    url: str, current: Settings, duration: float | None, vehicles: int, *, rl: bool
) -> None:
    # the migrations, the seed and the policy store: imported by a demo that runs, not by --help
    from app.migrate import upgrade
    from app.policies.service import ManifestConflict, assign_shipped_policies
    from app.seed import seed

    engine = make_sync_engine(url)
    upgrade(engine)
    admin_password = new_password()
    try:
        with session_scope(engine) as session:
            counts = seed(session)
            save_user(session, DEMO_ADMIN, "admin", admin_password)
            policies = assign_shipped_policies(session) if rl else {}
    except ManifestConflict as error:
        raise CliError(
            f"demo --rl: {error}; the kept database holds it as an earlier run stored it, and a "
            "stored policy's manifest never changes: run the demo without --keep"
        ) from None
    finally:
        engine.dispose()
    public = (current.public_url or f"http://{current.host}:{current.port}").rstrip("/")
    _say_whole(f"smoothfleet demo: database {redact(url)}")
    _say_whole(f"seeded {counts.vehicles} vehicles on {counts.i24_segments} sub-segments")
    for controller, sha256 in counts.policies.items():
        _say_whole(f"{controller}: policy {sha256[:12]} held for the seeded cars that run it")
    for controller, sha256 in policies.items():
        _say_whole(f"{controller}: policy {sha256[:12]} assigned to every car it can drive")
        if controller not in counts.policies:
            # The roster follows the simulator's verdict; --rl overrides it, and says so.
            _say_whole(
                f"{controller}: the seed roster does not run it (the simulator's verdict is not "
                "to assign it: docs/simulation.md); --rl runs it as the paper's fleet did"
            )
    _say_whole(f"dashboard: {public}/   login: {DEMO_ADMIN} / {admin_password} (new each run)")
    _say_whole(f"API docs: {public}/docs   health: {public}/readyz   (Ctrl-C stops)")
    try:
        summary = run_demo(url, current, duration_s=duration, vehicles=vehicles, say=_say_whole)
    except DemoError as error:
        raise CliError(f"demo: {error}") from None
    for line in summary.lines():
        _say_whole(line)
