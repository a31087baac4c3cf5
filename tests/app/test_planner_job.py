"""The planner as a job: its schedule inside `serve`, failures counted and recorded, and the
`smoothfleet planner once | run | replay` commands."""

from __future__ import annotations

import re
import signal
import subprocess
import time
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from prometheus_client import REGISTRY
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.plans.jobs import run_planner
from planner.recommended import RECOMMENDED_PLANNER, RECOMMENDED_PLANNER_PARAMS
from planner.warehouse import CycleOutcome
from smoothfleet.cli.planner import describe
from tests.planner.facts import inrix_snapshot, standing_slowdown
from tests.support.servers import (
    cli_env,
    free_port,
    live_server,
    run_cli,
    smoothfleet_command,
    wait_until_ready,
)


def recent_inrix(engine: Engine) -> None:
    now = datetime.now(UTC)
    for minute in (5, 4, 3):
        inrix_snapshot(engine, now - timedelta(minutes=minute), standing_slowdown())


def runs(engine: Engine) -> list[tuple[str, str]]:
    with engine.connect() as connection:
        return [
            (row.corridor_id, row.status)
            for row in connection.execute(
                text("SELECT corridor_id, status FROM plan_run ORDER BY plan_id")
            )
        ]


def wait_for(condition: object, timeout_s: float = 20.0) -> None:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():  # type: ignore[operator]
            return
        time.sleep(0.2)
    raise AssertionError("timed out")


def test_serve_runs_the_planner_on_its_schedule(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    recent_inrix(seeded_engine)
    with live_server(seeded_database_url, planner_period_s=1):
        wait_for(lambda: ("I-24-WB", "published") in runs(seeded_engine))


def busy_cycles(corridor_id: str) -> float:
    """This process's planner cycles that left the corridor to another planner."""
    value = REGISTRY.get_sample_value(
        "smoothfleet_planner_runs_total", {"corridor": corridor_id, "status": "busy"}
    )
    return value or 0.0


def test_servers_plan_as_they_start_and_two_replicas_publish_one_plan(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The first cycle waited a whole period after a (re)start, so the fleet ran on a plan
    aging towards `valid_until`, or on none. Two replicas starting together each run their
    first cycle at once: the advisory lock (or the plan published moments ago) leaves one."""
    recent_inrix(seeded_engine)
    busy_before = busy_cycles("I-24-WB")
    period_s = 120  # the old schedule's first cycle came no sooner
    started = time.monotonic()
    with (
        live_server(seeded_database_url, planner_period_s=period_s, plan_valid_for_s=300),
        live_server(seeded_database_url, planner_period_s=period_s, plan_valid_for_s=300),
    ):
        wait_for(lambda: runs(seeded_engine) and busy_cycles("I-24-WB") == busy_before + 1, 60)
        assert time.monotonic() - started < period_s
        assert runs(seeded_engine) == [("I-24-WB", "published")]


def test_no_planner_means_no_plans(seeded_database_url: str, seeded_engine: Engine) -> None:
    recent_inrix(seeded_engine)
    with live_server(seeded_database_url, planner_period_s=1, planner_enabled=False):
        time.sleep(3)
    assert runs(seeded_engine) == []


def test_a_failing_cycle_is_recorded_counted_and_the_others_still_run(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    recent_inrix(seeded_engine)
    with seeded_engine.begin() as connection:  # a corridor set up without its INRIX segments
        connection.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m, "
                "speed_limit_mps, min_target_speed_mps) "
                "VALUES ('HALF-DONE', 'test', 'east', 2, 200, 30, 9)"
            )
        )
    settings = load_settings(database_url=seeded_database_url)
    outcomes = {outcome.corridor_id: outcome for outcome in run_planner(seeded_engine, settings)}
    assert outcomes["I-24-WB"].status == "published"
    failed = outcomes["HALF-DONE"]
    assert failed.status == "failed"
    assert failed.reason == "UnknownCorridor: corridor 'HALF-DONE' has no sub-segments"
    with seeded_engine.connect() as connection:
        row = connection.execute(
            text("SELECT status, reason FROM plan_run WHERE corridor_id = 'HALF-DONE'")
        ).one()
    assert tuple(row) == ("failed", failed.reason)
    with live_server(seeded_database_url, planner_enabled=False) as base:
        exposition = httpx.get(f"{base}/metrics", timeout=10).text
    assert 'smoothfleet_planner_runs_total{corridor="HALF-DONE",status="failed"} 1.0' in exposition
    assert 'smoothfleet_planner_runs_total{corridor="I-24-WB",status="published"}' in exposition


def test_once_then_replay_from_the_command_line(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    recent_inrix(seeded_engine)
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    once = run_cli("planner", "once", env=env)
    assert once.returncode == 0, once.stderr
    assert "I-24-WB: published plan 1 in" in once.stdout
    assert "(0 vehicles, 0 pings, INRIX 1" in once.stdout  # ~180 s old
    # Planned as the simulator recommends, by default.
    with seeded_engine.connect() as connection:
        algorithm, params = connection.execute(
            text("SELECT algorithm, params FROM plan_run WHERE plan_id = 1")
        ).one()
    assert algorithm == RECOMMENDED_PLANNER
    assert {name: params[name] for name in RECOMMENDED_PLANNER_PARAMS} == dict(
        RECOMMENDED_PLANNER_PARAMS
    )
    replay = run_cli("planner", "replay", "--plan-id", "1", env=env)
    assert replay.returncode == 0, replay.stderr
    assert f"plan 1 (I-24-WB, {RECOMMENDED_PLANNER}): recomputed 632 targets, matches" in (
        replay.stdout
    )
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE fact_speed_planner SET target_speed_mps = 1 WHERE lane = 1")
        )
    differs = run_cli("planner", "replay", "--plan-id", "1", env=env)
    assert differs.returncode == 1
    assert "DIFFERS" in differs.stdout


def test_command_line_mistakes_get_one_line(seeded_database_url: str) -> None:
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    unknown = run_cli("planner", "once", "--corridor", "I-40-EB", env=env)
    assert unknown.returncode == 1
    assert unknown.stderr.strip() == (
        "smoothfleet: error: planner: unknown corridor I-40-EB (known: I-24-WB)"
    )
    missing = run_cli("planner", "replay", "--plan-id", "42", env=env)
    assert missing.returncode == 1
    assert missing.stderr.strip() == "smoothfleet: error: planner replay: no plan 42"
    bad_params = run_cli(
        "planner", "once", env={**env, "SMOOTHFLEET_PLANNER_PARAMS": '{"window_m": 0}'}
    )
    assert bad_params.returncode == 1
    assert bad_params.stderr.strip() == (
        "smoothfleet: error: SMOOTHFLEET_PLANNER_PARAMS: planner parameter window_m: "
        "Input should be greater than 0"
    )


def test_planner_run_keeps_publishing_until_stopped(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    recent_inrix(seeded_engine)
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url, SMOOTHFLEET_PLANNER_PERIOD_S="1")
    log = tmp_path / "planner.log"
    with log.open("w") as output:
        process = subprocess.Popen(
            [*smoothfleet_command(), "planner", "run"], env=env, stdout=output, stderr=output
        )
        try:
            wait_for(lambda: runs(seeded_engine).count(("I-24-WB", "published")) >= 2, 60)
        finally:
            process.send_signal(signal.SIGTERM)
            process.wait(timeout=30)
    assert process.returncode == 128 + signal.SIGTERM, log.read_text()
    assert f"planner: every 1 s, algorithm {RECOMMENDED_PLANNER}" in log.read_text()


def test_serve_no_planner_publishes_nothing(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    recent_inrix(seeded_engine)
    port = free_port()
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url, SMOOTHFLEET_PLANNER_PERIOD_S="1")
    log = tmp_path / "serve.log"
    with log.open("w") as output:
        server = subprocess.Popen(
            [*smoothfleet_command(), "serve", "--no-planner", "--port", str(port)],
            env=env,
            stdout=output,
            stderr=output,
        )
        try:
            wait_until_ready(f"http://127.0.0.1:{port}")
            time.sleep(3)  # three periods
        finally:
            server.send_signal(signal.SIGTERM)
            server.wait(timeout=30)
    assert runs(seeded_engine) == [], log.read_text()


def test_a_plan_standing_on_old_readings_says_so() -> None:
    """A partial outage: one segment read 8 s ago, the rest carried from 568 s ago. The line
    said 'INRIX 8 s old' and nothing else (planner audit)."""
    inputs = {"vehicles": 0, "pings": 0, "inrix_age_s": 8.1, "inrix_oldest_reading_age_s": 568.2}
    line = describe(CycleOutcome("I-24-WB", "published", 7, None, 12.0, inputs))
    assert line.endswith("INRIX 8 s old, some segments' reading 568 s old)")
    whole = {**inputs, "inrix_oldest_reading_age_s": 8.1}
    assert describe(CycleOutcome("I-24-WB", "published", 7, None, 12.0, whole)).endswith(
        "INRIX 8 s old)"
    )


def _gauge(exposition: str, series: str) -> float:
    """The value of one series in a Prometheus text exposition."""
    found = re.search(rf"^{re.escape(series)} (\S+)$", exposition, re.MULTILINE)
    assert found is not None, f"no {series} in /metrics"
    return float(found.group(1))


def test_metrics_show_plans_and_inrix_that_other_processes_made(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """In the compose layout the planner runs in its own process and the poller writes to the
    database: the API's /metrics never saw a planner run or a polled reading (ops audit)."""
    recent_inrix(seeded_engine)
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)
    assert run_cli("planner", "once", env=env).returncode == 0
    with seeded_engine.connect() as connection:
        published, started = connection.execute(
            text("SELECT published_at, started_at FROM plan_run WHERE status = 'published'")
        ).one()
        measured = connection.execute(text("SELECT max(measured_at) FROM fact_inrix_estimate"))
        newest_reading = measured.scalar_one()
    with live_server(seeded_database_url, planner_enabled=False) as base:
        exposition = httpx.get(f"{base}/metrics", timeout=10).text

    assert _gauge(exposition, "smoothfleet_warehouse_up") == 1.0
    corridor = '{corridor="I-24-WB"}'
    assert _gauge(
        exposition, f"smoothfleet_warehouse_plan_published_timestamp_seconds{corridor}"
    ) == pytest.approx(published.timestamp())
    assert _gauge(
        exposition,
        'smoothfleet_warehouse_plan_run_timestamp_seconds{corridor="I-24-WB",status="published"}',
    ) == pytest.approx(started.timestamp())
    assert _gauge(
        exposition, f"smoothfleet_warehouse_inrix_measured_timestamp_seconds{corridor}"
    ) == pytest.approx(newest_reading.timestamp())
