"""`smoothfleet demo` closes the whole loop: server, planner, INRIX feed and a fleet of real agents.

A short run with a few vehicles (the full 100-vehicle run is for the command line): at the end
the plans are published, every vehicle of the fleet has pings stored, some of them driving on
the plan, and the feed's snapshots are in the warehouse.
"""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

import pytest
from sqlalchemy import Engine, text
from sqlalchemy.orm import Session

from planner.warehouse import replay_plan
from smoothfleet.cli.common import CliError
from smoothfleet.cli.demo import one_demo_per_data_dir
from tests.support.servers import cli_env, free_port, run_cli
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

VEHICLES = 6


@pytest.mark.slow
def test_demo_closes_the_loop(database_url: str, engine: Engine, tmp_path: Path) -> None:
    result = run_cli(
        "demo",
        "--port",
        str(free_port()),
        "--duration",
        "30",
        "--vehicles",
        str(VEHICLES),
        "--rl",  # the cars run the committed policies, each downloaded by sha256 from the server
        env=cli_env(SMOOTHFLEET_DATABASE_URL=database_url, SMOOTHFLEET_DATA_DIR=str(tmp_path)),
        timeout=400,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert f"with {VEHICLES} vehicles" in result.stdout
    assert f"from {VEHICLES} vehicles" in result.stdout
    # --rl puts the ACC cars on rl_acc, which the roster (the simulator's verdict) does not run
    assert "rl_acc: the seed roster does not run it" in result.stdout
    assert "rl_accel: the seed roster does not run it" not in result.stdout
    # the status line, every 5 s, in the pages' words
    reporting = re.findall(r"pings .* · reporting (\d+)/100 · cleared \d+ · ", result.stdout)
    assert reporting, result.stdout
    assert int(reporting[-1]) == VEHICLES  # of the 100 in the roster
    assert re.search(r"clearance: \d+ cars cleared, \d+ verdict changes after", result.stdout)
    with engine.connect() as connection:
        pinging = connection.execute(
            text("SELECT vehicle_id, count(*) FROM fact_vehicle_ping GROUP BY vehicle_id")
        ).all()
        engaged = connection.execute(
            text("SELECT count(*) FROM fact_vehicle_ping WHERE is_controller_engaged")
        ).scalar_one()
        plans = connection.execute(
            text("SELECT count(*) FROM plan_run WHERE status = 'published'")
        ).scalar_one()
        snapshots = connection.execute(
            text("SELECT count(DISTINCT measured_at) FROM fact_inrix_estimate")
        ).scalar_one()
        statuses = connection.execute(
            text("SELECT count(DISTINCT vehicle_id) FROM fact_vehicle_status")
        ).scalar_one()
        policies = dict(
            connection.execute(
                text(
                    "SELECT v.actuation, array_agg(DISTINCT p.policy_sha256) "
                    "FILTER (WHERE p.controller IS NOT NULL) "
                    "FROM fact_vehicle_ping AS p JOIN dim_vehicle AS v USING (vehicle_id) "
                    "GROUP BY v.actuation"
                )
            ).all()
        )
    assert len(pinging) == VEHICLES
    assert all(count >= 10 for _, count in pinging)
    assert plans >= 1
    assert engaged > 0
    assert snapshots >= 15  # the 15-minute backfill and the live minutes
    assert statuses == VEHICLES
    for actuation, running in policies.items():
        shipped = BUNDLED_POLICIES / f"rl_{actuation}.npz"
        assert running == [hashlib.sha256(shipped.read_bytes()).hexdigest()]
    assert "acc" in policies
    assert "rl_acc: policy " in result.stdout
    assert "rl_accel: policy " in result.stdout
    # every agent handed its car back and uploaded its spool before the demo ended
    for spool in tmp_path.glob("demo/*/spools/*.sqlite"):
        assert spool.stat().st_size > 0
    with engine.connect() as connection:
        live_tokens = connection.execute(
            text("SELECT count(*) FROM api_token WHERE revoked_at IS NULL")
        ).scalar_one()
        plan_ids = connection.execute(
            text("SELECT plan_id FROM plan_run WHERE status = 'published' ORDER BY plan_id")
        ).scalars()
    assert live_tokens == 0, "the run's cars' and feed's tokens must end with it"
    # Spools uploaded at the end carry pings of the plans' windows that arrived after the plans
    # read them: every plan still replays to its stored targets bit for bit.
    with Session(engine) as session:
        reports = [replay_plan(session, plan_id) for plan_id in plan_ids]
    assert reports
    assert [(r.max_difference_mps, r.buffer_cells_differing) for r in reports] == [(0.0, 0)] * len(
        reports
    )


def test_the_demo_finds_its_traffic_drive_where_every_command_finds_the_shared_data(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """It looked beside its own file alone: installed other than in editable mode, it ran
    synthetic waves whatever SMOOTHFLEET_SHARED_DATA said."""
    from smoothfleet.cli.demo import TRAFFIC_DRIVE_FILE, traffic_drive_path

    monkeypatch.setenv("SMOOTHFLEET_SHARED_DATA", str(tmp_path / "data"))
    assert traffic_drive_path() == tmp_path / "data" / TRAFFIC_DRIVE_FILE


def test_a_second_demo_on_the_same_data_dir_is_refused_naming_the_first(tmp_path: Path) -> None:
    """A second demo on the data dir (another port, another terminal) dropped the running
    one's database, which went on failing in its server log and printed the second's pings."""
    with one_demo_per_data_dir(tmp_path):
        with (
            pytest.raises(
                CliError, match=rf"a demo is already running on .* \(pid {os.getpid()}\)"
            ),
            one_demo_per_data_dir(tmp_path),
        ):
            pass
    with one_demo_per_data_dir(tmp_path):  # the first ended: the next may run
        pass
