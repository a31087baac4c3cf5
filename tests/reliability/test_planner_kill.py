"""Kill the planner mid-run: no half plan is ever visible, and the next run publishes.

To kill it at a known point, the test holds a lock that makes the planner's insert of plan rows
wait: the planner process is then inside its publishing transaction (plan_run written, rows not
yet), and that is when it is SIGKILLed.
"""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.plans.jobs import run_planner
from tests.planner.facts import inrix_snapshot, standing_slowdown
from tests.support.servers import cli_env, live_server, smoothfleet_command
from tests.support.tokens import bearer, issue

HALF_PLANS = text(
    """
    SELECT count(*) FROM plan_run r
    WHERE r.status = 'published'
      AND (SELECT count(DISTINCT lane) FROM fact_speed_planner p
           WHERE p.corridor_id = r.corridor_id AND p.plan_id = r.plan_id) <> 4
    """
)
PLANNER_WAITING = text(
    """
    SELECT count(*) FROM pg_stat_activity
    WHERE datname = current_database() AND wait_event_type = 'Lock'
      AND query ILIKE '%INSERT INTO fact_speed_planner%'
    """
)


def wait_for(condition: Callable[[], bool], timeout_s: float = 60) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.1)


def scalar(engine: Engine, query: text) -> int:  # type: ignore[valid-type]
    with engine.connect() as connection:
        return int(connection.execute(query).scalar_one())


@pytest.mark.slow
def test_a_planner_killed_while_publishing_leaves_no_half_plan_and_the_next_run_publishes(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path
) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    for minutes_ago in range(6, 1, -1):
        inrix_snapshot(seeded_engine, now - timedelta(minutes=minutes_ago), standing_slowdown())
    (first,) = run_planner(seeded_engine, load_settings(database_url=seeded_database_url))
    assert first.status == "published"
    viewer = bearer(issue(seeded_engine, "viewer"))
    env = cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url)

    with live_server(seeded_database_url, planner_enabled=False) as base:
        latest = f"{base}/api/v1/plans/latest?corridor=I-24-WB"
        with seeded_engine.connect() as blocker:
            blocker.execute(text("LOCK TABLE fact_speed_planner IN EXCLUSIVE MODE"))
            with (tmp_path / "planner.log").open("w") as log:
                planner = subprocess.Popen(
                    [*smoothfleet_command(), "planner", "once"],
                    env=env,
                    stdout=log,
                    stderr=subprocess.STDOUT,
                )
            wait_for(lambda: scalar(seeded_engine, PLANNER_WAITING) == 1)
            # Mid-run: readers still see the previous, complete plan.
            during = httpx.get(latest, headers=viewer, timeout=10)
            assert during.status_code == 200
            assert during.json()["plan_id"] == first.plan_id
            planner.send_signal(signal.SIGKILL)
            planner.wait(timeout=30)
            blocker.rollback()  # releases the lock: the orphaned transaction can only abort
        wait_for(lambda: scalar(seeded_engine, PLANNER_WAITING) == 0)
        with seeded_engine.connect() as connection:
            runs = connection.execute(text("SELECT plan_id FROM plan_run ORDER BY plan_id"))
            assert list(runs.scalars()) == [first.plan_id]
        assert scalar(seeded_engine, HALF_PLANS) == 0
        after_kill = httpx.get(latest, headers=viewer, timeout=10)
        assert after_kill.json()["plan_id"] == first.plan_id

        rerun = subprocess.run(
            [*smoothfleet_command(), "planner", "once"],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert rerun.returncode == 0, rerun.stderr
        fresh = httpx.get(latest, headers=viewer, timeout=10).json()
        assert fresh["plan_id"] > first.plan_id
        assert [lane["lane"] for lane in fresh["lanes"]] == [1, 2, 3, 4]
        assert scalar(seeded_engine, HALF_PLANS) == 0
