"""A simulated fleet rides out server and database outages (issue 14's done-when).

Five cars of the roster (Rogue, XT5, RAV4: both actuations) run the real agent on emulated cars,
in step with the wall clock, against `smoothfleet serve` as a process:
- the server is SIGKILLed: every car stays engaged on its last plan until that plan's own
  `valid_until`, then hands back; after the restart every car re-engages, and every ping it
  spooled is stored exactly once;
- PostgreSQL is stopped 20 s with the server up: no car disengages, and the server keeps
  serving the plans it holds (their documents are cached, their validity known).

The plans are made valid for 40 s (SMOOTHFLEET_PLAN_VALID_FOR_S; 180 s in production) and the
server stays away 50 s, so the test takes about a minute and a half rather than the issue's 120 s
outage with 3-minute plans: the behaviour (engaged until valid_until, whatever the network does)
is the same at either scale. 40 s leaves the cars their 20 s to engage and still 10 s of plan
after the kill.
"""

from __future__ import annotations

import contextlib
import signal
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.core.db import make_sync_engine
from app.plans.jobs import run_planner
from sim.emulator.rig import Rig, rig
from tests.planner.facts import INRIX_CODES, inrix_snapshot
from tests.reliability.conftest import Cluster
from tests.support.servers import (
    cli_env,
    free_port,
    smoothfleet_command,
    stop_gracefully,
    wait_until_ready,
)
from tests.support.tokens import issue
from vehicle_agent.engage import Mode
from vehicle_agent.server import ServerClient

pytestmark = pytest.mark.slow

# vehicle id -> emulated car (seed roster: make and actuation agree)
FLEET = {
    "SF-001": "nissan_rogue",
    "SF-010": "nissan_rogue",
    "SF-085": "cadillac_xt5",
    "SF-098": "toyota_rav4",
    "SF-099": "toyota_rav4",
}
PLAN_VALID_FOR_S = 40.0
SERVER_AWAY_S = 50.0
DATABASE_AWAY_S = 20.0
STEP_S = 0.1  # the agent's control period
# A car hands back at the first control step after valid_until by its own clock (0.1 s steps);
# the windows are read by that clock, so this is the step with room to spare.
HAND_BACK_WITHIN_S = 1.0


# Each car's emulated clock (its wall and steady clock in one) runs this far ahead of the wall
# clock at most. Started at the wall's last whole second and caught up in bursts from behind,
# it was behind the wall by up to 0.7 s when a plan arrived, and then ran faster than the wall
# while it caught up: the plan's age since arrival by that clock (which bounds its validity, as
# a real steady clock does) reached valid_until before the wall did, and the car handed back
# early by either clock. Ahead of the wall, a plan arrives after its publication by the car's
# clock too, as on a car.
CLOCK_LEAD_S = 2.0


@dataclass
class Fleet:
    """The cars, and every (car time, vehicle, engaged) they went through: the car judges
    valid_until by its own clock."""

    cars: dict[str, Rig]
    history: list[tuple[datetime, str, bool]] = field(default_factory=list)

    def drive(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        """Advance every car with the wall clock (the server judges plans by it), each car's
        clock kept up to `CLOCK_LEAD_S` ahead of it."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ahead = datetime.now(UTC) + timedelta(seconds=CLOCK_LEAD_S)
            for vehicle_id, car in self.cars.items():
                while car.clock.now() < ahead:
                    car.run(STEP_S, network=True)
                    self.history.append((car.clock.now(), vehicle_id, self.engaged(vehicle_id)))
            if until is not None and until():
                return
            time.sleep(0.02)

    def engaged(self, vehicle_id: str) -> bool:
        return self.cars[vehicle_id].agent.state.mode is Mode.ENGAGED

    def drained(self) -> bool:
        """Every spooled ping acknowledged by the server."""
        return all(car.agent.spool.backlog() == 0 for car in self.cars.values())

    def all_engaged(self) -> bool:
        return all(self.engaged(vehicle_id) for vehicle_id in self.cars)

    def mark(self) -> int:
        """Where the history stands now, for `engaged_in`."""
        return len(self.history)

    def engaged_in(
        self,
        start: int,
        stop: int | None = None,
        *,
        since: datetime | None = None,
        until: datetime | None = None,
    ) -> dict[str, set[bool]]:
        """Per vehicle, the engaged states recorded between two `mark`s, at car times within
        [since, until] where given. (Marks, not wall times: a car's clock runs ahead.)"""
        seen: dict[str, set[bool]] = {vehicle_id: set() for vehicle_id in self.cars}
        for moment, vehicle_id, engaged in self.history[start:stop]:
            if (since is None or since <= moment) and (until is None or moment <= until):
                seen[vehicle_id].add(engaged)
        return seen


def publish_plan(database_url: str, engine: Engine, valid_for_s: float) -> datetime:
    """A real planner run on fresh free-flow INRIX minutes; returns the plan's valid_until."""
    now = datetime.now(UTC)
    for minute in range(11, 1, -1):
        inrix_snapshot(engine, now - timedelta(minutes=minute), [25.0] * len(INRIX_CODES))
    settings = load_settings(
        database_url=database_url, plan_valid_for_s=valid_for_s, planner_period_s=valid_for_s / 2
    )
    (outcome,) = run_planner(engine, settings, now=now)
    assert outcome.status == "published", outcome.reason
    return now + timedelta(seconds=valid_for_s)


def start_server(database_url: str, port: int, log: Path) -> subprocess.Popen[bytes]:
    """`smoothfleet serve` (no planner: the test publishes), answering /readyz."""
    with log.open("a") as out:
        server = subprocess.Popen(
            [*smoothfleet_command(), "serve", "--no-migrate", "--no-planner"],
            env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url, SMOOTHFLEET_PORT=str(port)),
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    wait_until_ready(f"http://127.0.0.1:{port}")
    return server


@contextlib.contextmanager
def fleet_on(base: str, engine: Engine, tmp_path: Path, dbc_cache: Path) -> Iterator[Fleet]:
    """The five cars, their ACC set by their drivers, talking to the server at `base`."""
    with contextlib.ExitStack() as stack:
        http = stack.enter_context(httpx.Client(base_url=base))
        cars = {}
        for vehicle_id, key in FLEET.items():
            token = issue(engine, "vehicle", vehicle_id)
            cars[vehicle_id] = stack.enter_context(
                rig(
                    key,
                    tmp_path / vehicle_id,
                    dbc_cache,
                    controller="unused",
                    vehicle_id=vehicle_id,
                    server=ServerClient(http, vehicle_id, token),
                    speed_mps=24.0,
                    # ahead of the wall from its first step: its first poll fetches the plan
                    start=datetime.now(UTC) + timedelta(seconds=CLOCK_LEAD_S),
                )
            )
        fleet = Fleet(cars)
        fleet.drive(1.0)
        for car in cars.values():
            car.emulator.driver_engage(set_speed_mph=54)
        fleet.drive(20.0, until=fleet.all_engaged)
        assert fleet.all_engaged(), {v: c.agent.state.reason for v, c in cars.items()}
        yield fleet


def stored_pings(engine: Engine) -> dict[str, list[datetime]]:
    with engine.connect() as connection:
        rows = connection.execute(
            text("SELECT vehicle_id, ts FROM fact_vehicle_ping ORDER BY vehicle_id, ts")
        ).all()
    stored: dict[str, list[datetime]] = {}
    for vehicle_id, ts in rows:
        stored.setdefault(vehicle_id, []).append(ts)
    return stored


def test_a_server_kill_leaves_every_car_on_its_plan_until_valid_until(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    log = tmp_path / "serve.log"
    server = start_server(seeded_database_url, port, log)
    valid_until = publish_plan(seeded_database_url, seeded_engine, PLAN_VALID_FOR_S)
    try:
        with fleet_on(base, seeded_engine, tmp_path, dbc_cache) as fleet:
            # the server is gone (SIGKILL: no goodbye), the plan still has a while to run
            server.send_signal(signal.SIGKILL)
            server.wait(timeout=10)
            killed_at, killed = datetime.now(UTC), fleet.mark()
            assert valid_until - killed_at > timedelta(seconds=10), "engaging took too long"
            fleet.drive((valid_until - datetime.now(UTC)).total_seconds() + 3.0)
            before_expiry = fleet.engaged_in(killed, until=valid_until - timedelta(seconds=0.2))
            after_expiry = fleet.engaged_in(
                killed, since=valid_until + timedelta(seconds=HAND_BACK_WITHIN_S)
            )
            assert before_expiry == {vehicle_id: {True} for vehicle_id in FLEET}
            assert after_expiry == {vehicle_id: {False} for vehicle_id in FLEET}
            for car in fleet.cars.values():
                assert car.agent.state.reason == "no fresh plan"
                assert car.agent.stats.server_errors["plan"] >= 1
                assert car.agent.stats.plans_refused == 0
            fleet.drive(SERVER_AWAY_S - (datetime.now(UTC) - killed_at).total_seconds())
            # back: a new plan, and every car takes it up by itself
            server = start_server(seeded_database_url, port, log)
            publish_plan(seeded_database_url, seeded_engine, PLAN_VALID_FOR_S)
            fleet.drive(45.0, until=fleet.all_engaged)
            assert fleet.all_engaged(), {
                vehicle_id: car.agent.state.reason for vehicle_id, car in fleet.cars.items()
            }
            spooled = {
                vehicle_id: [ping["ts"] for _, ping in car.agent.spool.oldest(100_000)]
                for vehicle_id, car in fleet.cars.items()
            }
            fleet.drive(60.0, until=fleet.drained)
            assert fleet.drained()
    finally:
        stop_gracefully(server, log)
    stored = stored_pings(seeded_engine)
    for vehicle_id, car in fleet.cars.items():
        # every ping spooled is stored once: those sent before the kill, and the outage's
        assert len(stored[vehicle_id]) == car.agent.stats.pings_spooled, vehicle_id
        assert set(stored[vehicle_id]) >= {datetime.fromisoformat(ts) for ts in spooled[vehicle_id]}


def test_a_database_outage_disengages_no_car(
    cluster: Cluster, tmp_path: Path, dbc_cache: Path
) -> None:
    engine = make_sync_engine(cluster.url)
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    try:
        server = start_server(cluster.url, port, tmp_path / "serve.log")
        # valid long enough to outlast the outage: only the outage could end it
        valid_until = publish_plan(cluster.url, engine, 2 * PLAN_VALID_FOR_S)
        try:
            with fleet_on(base, engine, tmp_path, dbc_cache) as fleet:
                engine.dispose()
                stopped = fleet.mark()
                cluster.stop()
                fleet.drive(DATABASE_AWAY_S)
                cluster.start()
                back_at, back = datetime.now(UTC), fleet.mark()
                assert back_at < valid_until
                during = fleet.engaged_in(stopped, back)
                assert during == {vehicle_id: {True} for vehicle_id in FLEET}
                for car in fleet.cars.values():
                    # pings were refused 503 database_unavailable (they stay spooled) ...
                    assert car.agent.stats.server_errors["pings"] >= 1
                    # ... while the server kept serving the plan it held (304 to every poll)
                    assert car.agent.lane_plan is not None
                    assert car.agent.stats.server_errors["plan"] == 0
                # the agents send their backlog by themselves once the database answers
                fleet.drive(60.0, until=fleet.drained)
                assert fleet.drained()
        finally:
            stop_gracefully(server, tmp_path / "serve.log")
        stored = stored_pings(engine)
        for vehicle_id, car in fleet.cars.items():
            assert len(stored[vehicle_id]) == car.agent.stats.pings_spooled, vehicle_id
    finally:
        engine.dispose()
