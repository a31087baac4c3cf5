"""The agent against the real server on a real PostgreSQL: config, corridor and plan in, pings
and status reports out, and store-and-forward through a server outage and an agent restart."""

from __future__ import annotations

import json
import logging
import threading
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.plans.jobs import run_planner
from sim.emulator.rig import Rig
from tests.planner.facts import INRIX_CODES, inrix_snapshot
from tests.support.cars import car_served_by
from tests.support.servers import live_server
from tests.support.tokens import issue
from vehicle_agent.agent import CONFIG_REFRESH_S, FIRST_STATUS_WAIT_S
from vehicle_agent.engage import Mode
from vehicle_agent.server import ServerClient
from vehicle_agent.spool import PingSpool

pytestmark = pytest.mark.slow


def publish_free_flow_plan(database_url: str, engine: Engine) -> int:
    """A real planner run over ten minutes of 25 m/s INRIX readings."""
    now = datetime.now(UTC).replace(microsecond=0)
    for minute in range(12, 2, -1):
        inrix_snapshot(engine, now - timedelta(minutes=minute), [25.0] * len(INRIX_CODES))
    (outcome,) = run_planner(engine, load_settings(database_url=database_url), now=now)
    assert outcome.status == "published", outcome.reason
    return int(outcome.plan_id or 0)


def test_agent_takes_its_assignment_from_the_server_and_reports(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    plan_id = publish_free_flow_plan(seeded_database_url, seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-098")  # a RAV4 running rl_accel in lane 2
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-098", token, tmp_path, dbc_cache, make="toyota_rav4", speed_mps=24.0
        ) as r,
    ):
        r.run(1.0, network=True)
        config = r.agent.config
        assert config is not None
        assert (config.controller.name, config.assigned_lane) == ("rl_accel", 2)
        assert r.agent.lane_plan is not None
        assert r.agent.lane_plan.plan_id == plan_id
        r.emulator.driver_engage(set_speed_mph=54)
        r.run(10.0, network=True)
        assert r.agent.state.mode is Mode.ENGAGED, r.agent.state.reason
        r.run(15.0, network=True)
        r.agent.upload()
        assert r.agent.spool.backlog() == 0
        assert r.agent.stats.server_errors == {}
    with seeded_engine.connect() as connection:
        pings = connection.execute(
            text(
                "SELECT count(*), count(*) FILTER (WHERE is_controller_engaged), max(plan_id), "
                "count(x_m) FROM fact_vehicle_ping WHERE vehicle_id = 'SF-098'"
            )
        ).one()
        statuses = connection.execute(
            text(
                "SELECT count(*), bool_or(is_controller_running), max(plan_id), "
                "min(config_version) FROM fact_vehicle_status WHERE vehicle_id = 'SF-098'"
            )
        ).one()
    assert pings[0] >= 25
    assert pings[1] >= 10
    assert pings[2] == plan_id
    assert pings[3] == pings[0]  # every ping map-matched onto the corridor by the server
    assert statuses[0] >= 2
    assert statuses[1] is True
    assert statuses[2] == plan_id
    assert statuses[3] == config.config_version == 1  # the version it runs, echoed


def ping_keys(engine: Engine, vehicle_id: str = "SF-001") -> list[datetime]:
    with engine.connect() as connection:
        return list(
            connection.execute(
                text("SELECT ts FROM fact_vehicle_ping WHERE vehicle_id = :v ORDER BY ts"),
                {"v": vehicle_id},
            ).scalars()
        )


def test_every_spooled_ping_reaches_the_database_once_across_outage_and_restart(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-001")
    spool_path = tmp_path / "spool.sqlite"
    spooled: list[str] = []
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    # 1. Server up: 10 pings. The agent sends them, the server commits them, and the agent is
    #    killed before it can forget them (the worst moment).
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-001", token, tmp_path, dbc_cache, start=start, spool=PingSpool(spool_path)
        ) as first,
    ):
        first.run(9.95)
        rows = first.agent.spool.oldest(100)
        spooled += [ping["ts"] for _, ping in rows]
        answer = first.agent.server.post_pings([ping for _, ping in rows])  # type: ignore[union-attr]
        assert answer.accepted == len(rows) == 10
    # (killed: no shutdown, no spool.remove; the spool file stays as it was on disk)
    assert len(ping_keys(seeded_engine)) == 10
    # 2. Server down. The restarted agent keeps spooling; uploads fail and are retried later.
    with (
        httpx.Client(base_url=base) as dead,
        car_served_by(
            dead,
            "SF-001",
            token,
            tmp_path,
            dbc_cache,
            timeout_s=0.5,
            start=start + timedelta(seconds=30),
            spool=PingSpool(spool_path),
        ) as second,
    ):
        second.run(20.0, network=True)
        assert second.agent.stats.server_errors["pings"] >= 1
        assert second.agent.spool.backlog() == 30
        spooled = [ping["ts"] for _, ping in second.agent.spool.oldest(100)]
        # 3. The server comes back (same database, a new address): the backlog drains oldest
        #    first, the 10 pings sent before the crash count as duplicates.
        with (
            live_server(seeded_database_url, planner_enabled=False) as base_again,
            httpx.Client(base_url=base_again) as http_again,
        ):
            second.agent.server = ServerClient(http_again, "SF-001", token)
            uploaded = second.agent.upload()
        assert uploaded == 30
        assert second.agent.spool.backlog() == 0
    stored = ping_keys(seeded_engine)
    assert len(stored) == 30
    assert sorted(datetime.fromisoformat(ts) for ts in spooled) == stored


def test_without_a_plan_the_car_stays_on_its_acc_until_one_is_published(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    token = issue(seeded_engine, "vehicle", "SF-099")  # RAV4, lane 3
    with (
        live_server(seeded_database_url, planner_enabled=False, planner_period_s=60) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-099", token, tmp_path, dbc_cache, make="toyota_rav4", speed_mps=24.0
        ) as r,
    ):
        r.emulator.driver_engage(set_speed_mph=54)
        r.run(5.0, network=True)
        # 503 + Retry-After: 60: no plan held, the stock ACC drives, no request was sent.
        assert r.agent.lane_plan is None
        assert r.agent.state.mode is Mode.STOCK
        assert r.agent.state.reason == "no fresh plan"
        assert r.emulator.agent_frames == 0
        plan_id = publish_free_flow_plan(seeded_database_url, seeded_engine)
        r.run(50.0, network=True)
        assert r.agent.lane_plan is None  # Retry-After honoured
        r.run(15.0, network=True, until=lambda: r.agent.state.mode is Mode.ENGAGED)
        assert r.agent.lane_plan is not None
        assert r.agent.lane_plan.plan_id == plan_id
        held = r.agent.lane_plan
        assert r.agent.state.mode is Mode.ENGAGED, (
            f"{r.agent.state}; car clock {r.clock.now()} monotonic {r.clock.monotonic()}; plan "
            f"published {held.plan.published_at} valid until {held.plan.valid_until}"
        )


def test_a_lane_change_from_the_operators_never_leaves_the_car_without_its_lanes_plan(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    plan_id = publish_free_flow_plan(seeded_database_url, seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-098")  # lane 2
    operator = issue(seeded_engine, "operator")
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-098", token, tmp_path, dbc_cache, make="toyota_rav4", speed_mps=24.0
        ) as r,
    ):
        r.emulator.driver_engage(set_speed_mph=54)
        r.run(10.0, network=True, until=lambda: r.agent.state.mode is Mode.ENGAGED)
        assert r.agent.state.mode is Mode.ENGAGED
        assert r.agent.config is not None
        controller = r.agent.config.controller.model_dump()  # kept: only the lane changes
        changed = http.put(
            "/api/v1/vehicles/SF-098/assignment",
            json={"lane": 3, "route": "B", "controller": controller},
            headers={"Authorization": f"Bearer {operator}"},
        )
        assert changed.status_code == 200, changed.text
        # the server now assigns lane 3; the car polls plans with its own lane until it reads
        # the new config (the next plan answer names its version), then asks for lane 3
        r.run(70.0, network=True)
        config = r.agent.config
        assert config is not None
        assert (config.assigned_lane, config.config_version) == (3, 2)
        assert r.agent.lane_plan is not None
        assert (r.agent.lane_plan.lane, r.agent.lane_plan.plan_id) == (3, plan_id)
        assert r.agent.stats.plans_refused == 0
        assert "has no lane" not in caplog.text


def test_pings_a_server_refuses_for_now_stay_in_the_spool_until_it_takes_them(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A server whose clock is behind refuses every ping as "in the future". The agent deleted
    each refused ping from its spool: a server clock 6 minutes slow lost every car's pings."""
    token = issue(seeded_engine, "vehicle", "SF-002")
    ahead = datetime.now(UTC).replace(microsecond=0) + timedelta(minutes=10)

    def stored() -> int:
        with seeded_engine.connect() as connection:
            return int(
                connection.execute(
                    text("SELECT count(*) FROM fact_vehicle_ping WHERE vehicle_id = 'SF-002'")
                ).scalar_one()
            )

    before = stored()
    with (
        live_server(seeded_database_url, planner_enabled=False) as slow,
        httpx.Client(base_url=slow) as http,
        car_served_by(http, "SF-002", token, tmp_path, dbc_cache, start=ahead) as r,
    ):
        r.run(5.0)
        backlog = r.agent.spool.backlog()
        assert backlog >= 5
        with caplog.at_level(logging.WARNING, logger="vehicle_agent.uplink"):
            assert r.agent.upload() == 0
        assert r.agent.spool.backlog() == backlog
        # one line for the batch, not one a ping, every retry, on the car's SD card
        refusals = [
            m for m in caplog.messages if "ping" in m and ("refused" in m or "rejected" in m)
        ]
        assert refusals == [refusals[0]]
        assert f"refused {backlog} pings for now" in refusals[0]
        assert r.agent.stats.pings_held_back == backlog
        assert r.agent.spool.counter("rejected") == 0
        # the server's clock mended (here: it allows the car's 10 minutes): they all go
        with (
            live_server(seeded_database_url, planner_enabled=False, ping_max_future_s=3600) as ok,
            httpx.Client(base_url=ok) as http_ok,
        ):
            r.agent.server = ServerClient(http_ok, "SF-002", token)
            assert r.agent.upload() == backlog
        assert stored() == before + backlog
        # a ping refused for now is given up a day's deployment after its own time
        r.agent.server = ServerClient(http, "SF-002", token)
        r.run(3.0)
        held = r.agent.spool.backlog()
        r.clock.step_wall(13 * 3600.0)
        assert r.agent.upload() == held
        assert r.agent.spool.backlog() == 0
        assert r.agent.spool.counter("rejected") == held


def test_a_backlog_over_the_servers_body_limit_reaches_it_in_smaller_batches(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    """A server (or a proxy before it) with a smaller body limit refuses a car's backlog whole
    with 413. The agent sent the same batch again at every back-off: its spool never drained,
    and every later ping waited behind it until the spool's bound dropped them."""
    token = issue(seeded_engine, "vehicle", "SF-003")
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    with (
        live_server(seeded_database_url, planner_enabled=False, max_body_bytes=8192) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(http, "SF-003", token, tmp_path, dbc_cache, start=start) as r,
    ):
        r.run(60.0)
        backlog = [ping for _, ping in r.agent.spool.oldest(100)]
        assert len(backlog) == 60
        assert len(json.dumps({"pings": backlog})) > 8192  # over the limit in one batch
        uploads = [r.agent.upload() for _ in range(3)]
        assert sum(uploads) == 60, uploads
        assert r.agent.spool.backlog() == 0
        assert r.agent.spool.counter("rejected") == 0
        refused = r.agent.stats.server_errors["pings"]
        assert refused >= 1
        # the limit is remembered: the next minute's pings go without a refused request
        r.run(60.0)
        assert r.agent.upload() == 60
        assert r.agent.stats.server_errors["pings"] == refused
    stored = ping_keys(seeded_engine, "SF-003")
    assert len(stored) == 120
    assert [datetime.fromisoformat(ping["ts"]) for ping in backlog] == stored[:60]


class FirstConfigsRefused(httpx.BaseTransport):
    """The real server, but its first `refusals` config answers are 503 (a server busy at
    the fleet's start)."""

    def __init__(self, refusals: int) -> None:
        self.left = refusals
        self.inner = httpx.HTTPTransport()

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        if request.url.path.endswith("/config") and self.left > 0:
            self.left -= 1
            return httpx.Response(
                503,
                json={
                    "detail": "database unavailable, retry later",
                    "code": "database_unavailable",
                },
                headers={"Retry-After": "1"},
            )
        return self.inner.handle_request(request)

    def close(self) -> None:
        self.inner.close()


def test_the_first_status_report_waits_for_the_cars_first_config(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    """Sent before the config, the first report said the agent ran no controller, and the
    fleet page held that red for a whole hold period: at a demo's start half the fleet read
    "not cleared" while every car drove. It waits (at most 45 s) for the config and a control
    pass with it."""
    token = issue(seeded_engine, "vehicle", "SF-001")
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base, transport=FirstConfigsRefused(2)) as http,
        car_served_by(http, "SF-001", token, tmp_path, dbc_cache) as r,
    ):
        r.run(12.0, network=True)
        assert r.agent.config is not None
        assert r.agent.stats.server_errors["config"] == 2
    reports = status_rows(seeded_engine)
    assert reports
    assert reports[0] == (r.agent.config.controller.name, r.agent.config.config_version)


def test_a_car_that_gets_no_config_reports_so_once_its_wait_is_over(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    """The first report's wait for a config is bounded: a car that never gets one says so."""
    token = issue(seeded_engine, "vehicle", "SF-001")
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base, transport=FirstConfigsRefused(1000)) as http,
        car_served_by(http, "SF-001", token, tmp_path, dbc_cache) as r,
    ):
        r.run(FIRST_STATUS_WAIT_S - 1.0, network=True)
        assert not status_rows(seeded_engine)
        r.run(2.0, network=True)
        assert r.agent.config is None
    assert status_rows(seeded_engine) == [(None, None)]


def status_rows(engine: Engine) -> list[tuple[str | None, int | None]]:
    with engine.connect() as connection:
        return [
            (controller, version)
            for controller, version in connection.execute(
                text(
                    "SELECT controller, config_version FROM fact_vehicle_status "
                    "WHERE vehicle_id = 'SF-001' ORDER BY ts"
                )
            )
        ]


class PingAnswersLate(httpx.BaseTransport):
    """The real server, but the answer to a ping upload reaches the car only once `answer` is
    set, after the server committed the pings (a slow uplink); `committed` is set then."""

    def __init__(self) -> None:
        self.committed = threading.Event()
        self.answer = threading.Event()
        self.inner = httpx.HTTPTransport()

    def handle_request(self, request: httpx.Request) -> httpx.Response:
        response = self.inner.handle_request(request)
        if request.url.path != "/api/v1/pings":
            return response
        response.read()
        self.committed.set()
        self.answer.wait(timeout=30)
        return httpx.Response(response.status_code, json=response.json())

    def close(self) -> None:
        self.inner.close()


def stop_during_an_upload(
    r: Rig,
    transport: PingAnswersLate,
    caplog: pytest.LogCaptureFixture,
    *,
    answer_after_s: float | None,
) -> None:
    """The agent stopped (`shutdown`, as `run_agent` calls it once the network thread's join
    has timed out) while the server has committed an upload: its answer reaches the car
    `answer_after_s` into the stop, or (None) only after the stop is over."""
    uploading = threading.Thread(target=r.agent.upload)
    uploading.start()
    assert transport.committed.wait(timeout=10)
    if answer_after_s is not None:
        threading.Timer(answer_after_s, transport.answer.set).start()
    with caplog.at_level(logging.WARNING, logger="vehicle_agent"):
        r.agent.shutdown()
    transport.answer.set()
    uploading.join(timeout=10)
    assert not uploading.is_alive()


def test_pings_the_server_took_while_the_agent_stopped_are_never_sent_again(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A stop that outwaited the network thread closed the spool under its upload: the
    server's answer came, the spool could not forget the pings, and the next start sent them
    all again. The stop now waits for the answer of the upload in flight."""
    token = issue(seeded_engine, "vehicle", "SF-004")
    spool_path = tmp_path / "spool.sqlite"
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    transport = PingAnswersLate()
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base, transport=transport) as http,
        car_served_by(
            http, "SF-004", token, tmp_path, dbc_cache, start=start, spool=PingSpool(spool_path)
        ) as r,
    ):
        r.run(4.95)
        assert r.agent.spool.backlog() == 5
        stop_during_an_upload(r, transport, caplog, answer_after_s=0.5)
        assert r.agent.stats.pings_uploaded == 5
        assert r.agent.stats.spool_errors == 0
    assert PingSpool(spool_path).backlog() == 0  # the next start sends none of them again
    assert len(ping_keys(seeded_engine, "SF-004")) == 5
    assert "ping spool" not in caplog.text


def test_pings_whose_answer_never_came_before_the_stop_are_sent_again_and_stored_once(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The stop waits for an upload's answer only as long as the request may take: past
    that, the pings' fate is unknown to the car, so they stay spooled and go again at the
    next start, and the server counts them as duplicates rather than storing them twice."""
    token = issue(seeded_engine, "vehicle", "SF-005")
    spool_path = tmp_path / "spool.sqlite"
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    transport = PingAnswersLate()
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base, transport=transport) as http,
        car_served_by(
            http,
            "SF-005",
            token,
            tmp_path,
            dbc_cache,
            start=start,
            spool=PingSpool(spool_path),
            timeout_s=1.5,  # the stop waits 3 s for an answer
        ) as r,
    ):
        r.run(4.95)
        stop_during_an_upload(r, transport, caplog, answer_after_s=None)
        assert len(ping_keys(seeded_engine, "SF-005")) == 5
        restarted = PingSpool(spool_path)
        rows = restarted.oldest(100)
        assert len(rows) == 5
        with httpx.Client(base_url=base) as again:
            answer = ServerClient(again, "SF-005", token).post_pings([ping for _, ping in rows])
    assert (answer.accepted, answer.duplicates, answer.rejected) == (0, 5, [])
    assert len(ping_keys(seeded_engine, "SF-005")) == 5
    assert (
        "a ping upload still awaited the server's answer at the stop: its pings stay spooled "
        "and go again at the next start (the server counts those it took as duplicates)"
    ) in caplog.messages


def test_a_ping_a_clock_glitch_stamped_far_ahead_is_given_up_and_the_pings_around_it_arrive(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The server refuses a ping stamped past its window ahead as retryable (its own clock may
    be behind), and the car kept such a ping until 12 h after its own time: one a glitch
    stamped a day ahead stayed spooled for a day and a half, sent again with every upload,
    each of which then backed off."""
    token = issue(seeded_engine, "vehicle", "SF-006")
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(minutes=5)
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(http, "SF-006", token, tmp_path, dbc_cache, start=start) as r,
    ):
        r.run(2.95)
        r.clock.step_wall(86_400.0)  # the car's clock jumps a day ahead for a second
        r.run(1.0)
        r.clock.step_wall(-86_400.0)  # and is set right
        r.run(3.0)
        spooled = [ping["ts"] for _, ping in r.agent.spool.oldest(100)]
        assert len(spooled) == 7
        glitch = spooled[3]
        assert datetime.fromisoformat(glitch) > start + timedelta(days=1)
        ahead_s = (datetime.fromisoformat(glitch) - r.clock.now()).total_seconds()
        with caplog.at_level(logging.WARNING, logger="vehicle_agent.uplink"):
            assert r.agent.upload() == 7
        assert r.agent.spool.backlog() == 0
        assert r.agent.spool.counter("rejected") == 1
        assert r.agent.stats.pings_stamped_ahead == 1
        assert r.agent.stats.pings_held_back == 0
        assert [m.message for m in caplog.records if m.name == "vehicle_agent.uplink"] == [
            f"gave up 1 pings the server refused, stamped up to {ahead_s:.0f} s ahead of the car's "
            f"clock ({glitch}: ts is more than 300 s in the future): a clock that ran ahead "
            "stamped them"
        ]
    stored = ping_keys(seeded_engine, "SF-006")
    assert stored == [datetime.fromisoformat(ts) for ts in spooled if ts != glitch]


def test_a_shortened_status_period_applies_from_the_last_report(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    """The next report was set with the period of the config then: cut from 600 s to 5 s, the
    car waited out the 600 s before its first report at 5 s. Now the next report is one new
    period after the last (so at once, here, when the config refresh reads the new one)."""
    token = issue(seeded_engine, "vehicle", "SF-001")
    fast_server = live_server(seeded_database_url, planner_enabled=False, agent_status_period_s=5)
    with (
        live_server(seeded_database_url, planner_enabled=False, agent_status_period_s=600) as slow,
        httpx.Client(base_url=slow) as http,
        car_served_by(http, "SF-001", token, tmp_path, dbc_cache) as r,
    ):
        r.run(2.0, network=True)
        assert len(status_rows(seeded_engine)) == 1
        with (
            fast_server as fast,
            httpx.Client(base_url=fast) as http_fast,
        ):
            # the same database behind a server restarted with a shorter period
            r.agent.server = ServerClient(http_fast, "SF-001", token)
            r.run(CONFIG_REFRESH_S + 1.0, network=True)  # the refresh reads the 5 s period
            assert r.agent.config is not None
            assert r.agent.config.status_period_s == 5.0
            assert len(status_rows(seeded_engine)) == 2  # at the refresh, not 600 s on
            r.run(10.0, network=True)
    assert len(status_rows(seeded_engine)) == 4  # and every 5 s from there


@pytest.mark.parametrize("pulled_by", ["sql", "maintenance"])
def test_a_car_the_operators_pull_is_handed_back_within_a_plan_poll(
    pulled_by: str,
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
) -> None:
    """A car pulled from service (`active` false in SQL, or maintenance through the API) was
    commanded until its next config refresh, up to 60 s later. The next plan answer names the
    new config version (at most `plan_poll_s`, 5 s, later) and the car reads its config then."""
    publish_free_flow_plan(seeded_database_url, seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-098")
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-098", token, tmp_path, dbc_cache, make="toyota_rav4", speed_mps=24.0
        ) as r,
    ):
        r.emulator.driver_engage(set_speed_mph=54)
        r.run(10.0, network=True, until=lambda: r.agent.state.mode is Mode.ENGAGED)
        assert r.agent.state.mode is Mode.ENGAGED
        if pulled_by == "sql":
            with seeded_engine.begin() as connection:
                connection.execute(
                    text("UPDATE dim_vehicle SET is_active = false WHERE vehicle_id = 'SF-098'")
                )
        else:
            pulled = http.put(
                "/api/v1/vehicles/SF-098/maintenance",
                json={"in_maintenance": True, "note": "pulled"},
                headers={"Authorization": f"Bearer {issue(seeded_engine, 'operator')}"},
            )
            assert pulled.status_code == 200, pulled.text
        pulled_at = r.clock.monotonic()
        r.run(30.0, network=True, until=lambda: r.agent.state.mode is not Mode.ENGAGED)
        assert r.agent.state.reason == "agent not enabled for this vehicle"
        assert r.clock.monotonic() - pulled_at <= 5.0 + 1.0  # a plan poll and a network pass
        assert r.agent.config is not None
        assert r.agent.config.config_version == 2


def test_a_car_moved_where_its_lane_is_not_reads_its_new_config_within_a_plan_poll(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
) -> None:
    """A car reassigned to a corridor without the lane it polls gets 404 to every plan poll.
    The server names the new config version on that 404 too, and the agent read it only from
    the answers it took for success: the car went on following its old plan until its next
    refresh, up to 60 s (a review's reproduction). Here the corridor loses the car's lane and
    the car is moved to lane 1 (in SQL, the version bumped by migration 0022's trigger)."""
    publish_free_flow_plan(seeded_database_url, seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-098")  # lane 2
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
        car_served_by(
            http, "SF-098", token, tmp_path, dbc_cache, make="toyota_rav4", speed_mps=24.0
        ) as r,
    ):
        r.run(CONFIG_REFRESH_S / 2, network=True, until=lambda: r.agent.lane_plan is not None)
        assert r.agent.config is not None
        assert r.agent.config.assigned_lane == 2
        with seeded_engine.begin() as connection:
            connection.execute(
                text("UPDATE dim_corridor SET lanes = 1 WHERE corridor_id = 'I-24-WB'")
            )
            connection.execute(
                text("UPDATE dim_vehicle SET assigned_lane = 1 WHERE vehicle_id = 'SF-098'")
            )
        moved_at = r.clock.monotonic()
        r.run(30.0, network=True, until=lambda: r.agent.config.assigned_lane == 1)  # type: ignore[union-attr]
        assert r.agent.config.assigned_lane == 1
        assert r.clock.monotonic() - moved_at <= 5.0 + 2.0  # a plan poll and a network pass
