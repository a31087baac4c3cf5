"""A car and the real server's policies: the assigned policy is downloaded once over the API,
verified, run and reported in pings and status; a corrupted download never replaces the good
policy the car keeps, and leaves the car to its stock ACC until a good one arrives; a seeded
RAV4 runs the recommended policy the seed stored."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from pathlib import Path

import httpx
import numpy as np
import pytest
from sqlalchemy import Engine, text

from sim.emulator.rig import Rig
from sim.recommended import RECOMMENDED_CONTROLLER
from tests.support.cars import car_served_by
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue
from tests.vehicle_agent.test_agent_server import publish_free_flow_plan
from vehicle_agent.controllers.policy import save_policy
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES
from vehicle_agent.engage import Mode
from vehicle_agent.policies import PolicyStore
from vehicle_agent.spool import PingSpool

pytestmark = pytest.mark.slow

ACC_FILE = BUNDLED_POLICIES / "rl_acc.npz"
ACC_SHA256 = hashlib.sha256(ACC_FILE.read_bytes()).hexdigest()
RECOMMENDED_FILE = BUNDLED_POLICIES / f"{RECOMMENDED_CONTROLLER.controller}.npz"
RECOMMENDED_SHA256 = hashlib.sha256(RECOMMENDED_FILE.read_bytes()).hexdigest()


def car_of_sf001(
    http: httpx.Client,
    token: str,
    tmp_path: Path,
    dbc_cache: Path,
    store: PolicyStore,
    spool: PingSpool | None = None,
) -> AbstractContextManager[Rig]:
    """SF-001 (a Rogue in lane 1) driven by its agent against the live server."""
    return car_served_by(
        http, "SF-001", token, tmp_path, dbc_cache, speed_mps=24.0, spool=spool, policies=store
    )


def upload(http: httpx.Client, token: str, content: bytes, manifest: dict[str, object]) -> None:
    response = http.post(
        "/api/v1/policies",
        files={"policy": ("p.npz", content), "manifest": ("p.json", json.dumps(manifest))},
        headers=bearer(token),
    )
    assert response.status_code == 201, response.text


def assign(http: httpx.Client, token: str, sha256: str) -> None:
    body = {
        "lane": 1,
        "route": "A",
        "controller": {"name": "rl_acc", "params": {"policy_sha256": sha256}},
    }
    response = http.put("/api/v1/vehicles/SF-001/assignment", json=body, headers=bearer(token))
    assert response.status_code == 200, response.text


def small_acc_policy(tmp_path: Path) -> tuple[bytes, str]:
    """Another acc policy (a 6-4-2 network) to assign after the committed one."""
    rng = np.random.default_rng(7)
    path = tmp_path / "small.npz"
    digest = save_policy(
        path,
        "acc",
        [rng.normal(0, 0.1, (6, 4)), rng.normal(0, 0.1, (4, 2))],
        [np.zeros(4), np.zeros(2)],
    )
    return path.read_bytes(), digest


def flip_stored_byte(engine: Engine, sha256: str) -> None:
    """Damage (or, again, repair) one byte of a policy the server holds, keeping its size."""
    with engine.begin() as connection:
        connection.execute(
            text(
                "UPDATE dim_policy SET content = set_byte(content, 200, get_byte(content, 200) # 1)"
                " WHERE policy_sha256 = :sha256"
            ),
            {"sha256": sha256},
        )


def test_the_car_downloads_its_policy_once_runs_it_and_reports_its_hash(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    publish_free_flow_plan(seeded_database_url, seeded_engine)
    operator = issue(seeded_engine, "operator")
    token = issue(seeded_engine, "vehicle", "SF-001")
    policy_dir = tmp_path / "policies"
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
    ):
        manifest = json.loads(ACC_FILE.with_suffix(".json").read_text())
        upload(http, operator, ACC_FILE.read_bytes(), manifest)
        assign(http, operator, ACC_SHA256)
        with car_of_sf001(http, token, tmp_path, dbc_cache, PolicyStore(policy_dir)) as r:
            r.run(1.0, network=True)
            assert r.agent.assignment is not None
            assert r.agent.assignment.controller.policy_sha256 == ACC_SHA256
            assert (policy_dir / f"{ACC_SHA256}.npz").read_bytes() == ACC_FILE.read_bytes()
            r.emulator.driver_engage(set_speed_mph=54)
            r.run(20.0, network=True)
            assert r.agent.state.mode is Mode.ENGAGED, r.agent.state.reason
            r.run(5.0, network=True)
            r.agent.upload()
            assert r.agent.stats.policy_downloads == 1
            assert r.agent.stats.server_errors == {}
        fleet = http.get("/api/v1/fleet", headers=bearer(operator)).json()
        (car,) = [v for v in fleet["vehicles"] if v["vehicle_id"] == "SF-001"]
        assert car["last_ping"]["policy_sha256"] == ACC_SHA256
        assert car["last_status"]["policy_sha256"] == ACC_SHA256
        # restarted, the car finds the policy in its state dir and downloads nothing
        with car_of_sf001(
            http,
            token,
            tmp_path,
            dbc_cache,
            PolicyStore(policy_dir),
            spool=PingSpool(tmp_path / "second.sqlite"),
        ) as again:
            again.run(1.0, network=True)
            assert again.agent.assignment is not None
            assert again.agent.assignment.controller.policy_sha256 == ACC_SHA256
            assert again.agent.stats.policy_downloads == 0
    with seeded_engine.connect() as connection:
        pings = connection.execute(
            text(
                "SELECT count(*) FILTER (WHERE controller = 'rl_acc'), "
                "count(*) FILTER (WHERE policy_sha256 = :sha256), "
                "count(*) FILTER (WHERE is_controller_engaged AND policy_sha256 = :sha256), "
                "count(*) FILTER (WHERE controller IS NULL AND policy_sha256 IS NULL) "
                "FROM fact_vehicle_ping WHERE vehicle_id = 'SF-001'"
            ),
            {"sha256": ACC_SHA256},
        ).one()
        statuses = connection.execute(
            text(
                "SELECT count(*) FILTER (WHERE controller = 'rl_acc'), "
                "count(*) FILTER (WHERE policy_sha256 = :sha256) "
                "FROM fact_vehicle_status WHERE vehicle_id = 'SF-001'"
            ),
            {"sha256": ACC_SHA256},
        ).one()
    assert pings[0] >= 25
    assert pings[1] == pings[0]  # every ping with the controller names its policy
    assert pings[2] >= 5
    assert pings[3] <= 4  # at the start of each of the two runs, before the config arrived
    assert statuses[0] >= 2
    assert statuses[1] == statuses[0]  # every status with the controller names its policy


def test_a_seeded_rav4_downloads_verifies_and_runs_the_recommended_policy(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    """The seed roster gives its RAV4s the simulator's recommended controller on the shipped
    policy, and stores that policy: the car reads the assignment and fetches the file by sha256,
    with no upload by an operator."""
    publish_free_flow_plan(seeded_database_url, seeded_engine)
    token = issue(seeded_engine, "vehicle", "SF-098")  # the first RAV4
    policy_dir = tmp_path / "policies"
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
    ):
        config = http.get("/api/v1/vehicles/SF-098/config", headers=bearer(token))
        assert config.status_code == 200, config.text
        assert config.json()["controller"] == {
            "name": RECOMMENDED_CONTROLLER.controller,
            "params": {**RECOMMENDED_CONTROLLER.params, "policy_sha256": RECOMMENDED_SHA256},
        }
        with car_served_by(
            http,
            "SF-098",
            token,
            tmp_path,
            dbc_cache,
            make="toyota_rav4",
            speed_mps=24.0,
            policies=PolicyStore(policy_dir),
        ) as r:
            r.run(1.0, network=True)
            assert r.agent.stats.policy_downloads == 1
            # kept only because it hashed to its name and loaded as an accel policy
            assert (policy_dir / f"{RECOMMENDED_SHA256}.npz").read_bytes() == (
                RECOMMENDED_FILE.read_bytes()
            )
            assignment = r.agent.assignment
            assert assignment is not None
            assert assignment.controller.name == RECOMMENDED_CONTROLLER.controller
            assert assignment.controller.policy_sha256 == RECOMMENDED_SHA256  # as loaded
            r.emulator.driver_engage(set_speed_mph=54)
            r.run(20.0, network=True, until=lambda: r.agent.state.mode is Mode.ENGAGED)
            assert r.agent.state.mode is Mode.ENGAGED, r.agent.state.reason
            assert r.agent.snapshot is not None
            assert r.agent.snapshot.policy_sha256 == RECOMMENDED_SHA256  # what its pings say
            assert r.agent.stats.server_errors == {}


@contextmanager
def engaged_on_the_shipped_policy(
    database_url: str, engine: Engine, tmp_path: Path, dbc_cache: Path, store: PolicyStore
) -> Iterator[tuple[Rig, str, Callable[[], None]]]:
    """SF-001 engaged on the shipped acc policy, the small one stored beside it on the server:
    the rig, the small one's sha256, and a call that assigns it."""
    publish_free_flow_plan(database_url, engine)
    operator = issue(engine, "operator")
    token = issue(engine, "vehicle", "SF-001")
    small, small_sha256 = small_acc_policy(tmp_path)
    with (
        live_server(database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base) as http,
    ):
        manifest = json.loads(ACC_FILE.with_suffix(".json").read_text())
        upload(http, operator, ACC_FILE.read_bytes(), manifest)
        upload(http, operator, small, {"sha256": small_sha256, "actuation": "acc"})
        assign(http, operator, ACC_SHA256)
        with car_of_sf001(http, token, tmp_path, dbc_cache, store) as r:
            r.run(1.0, network=True)
            r.emulator.driver_engage(set_speed_mph=54)
            r.run(20.0, network=True, until=lambda: r.agent.state.mode is Mode.ENGAGED)
            assert r.agent.state.mode is Mode.ENGAGED, r.agent.state.reason
            yield r, small_sha256, lambda: assign(http, operator, small_sha256)


def test_a_corrupted_download_keeps_the_good_policy_and_hands_the_car_back(
    seeded_database_url: str, seeded_engine: Engine, tmp_path: Path, dbc_cache: Path
) -> None:
    store = PolicyStore(tmp_path / "policies")
    with engaged_on_the_shipped_policy(
        seeded_database_url, seeded_engine, tmp_path, dbc_cache, store
    ) as (r, small_sha256, assign_small):
        # the operators assign the small policy, whose bytes the server now serves damaged
        flip_stored_byte(seeded_engine, small_sha256)
        assign_small()
        r.run(65.0, network=True, until=lambda: r.agent.stats.policies_refused > 0)

        assert r.agent.stats.policies_refused == 1
        assert r.agent.assignment is None
        r.run(1.0, network=True)
        assert r.agent.state.mode is not Mode.ENGAGED
        # said as what it is, not as a car the operators disabled
        assert r.agent.state.reason == (
            "the assigned controller cannot run (its policy or parameters)"
        )
        assert sum(r.agent.stats.handbacks.values()) == 1
        assert store.holds(ACC_SHA256)  # the good policy is kept, untouched
        assert not store.path(small_sha256).exists()  # the bad download was never kept
        assert r.agent.snapshot is not None
        assert r.agent.snapshot.policy_sha256 is None  # and its pings say no policy runs
        # repaired on the server: the car's next try (back-off) gets the good bytes
        flip_stored_byte(seeded_engine, small_sha256)
        r.run(
            40.0,
            network=True,
            until=lambda: (
                r.agent.assignment is not None
                and r.agent.assignment.controller.policy_sha256 == small_sha256
            ),
        )
        assert r.agent.assignment is not None
        assert r.agent.assignment.controller.policy_sha256 == small_sha256
        assert store.holds(small_sha256)
        assert store.holds(ACC_SHA256)
        assert r.agent.stats.policy_downloads == 3  # acc once, small damaged, small good


def test_a_policy_the_car_cannot_keep_hands_back_and_backs_off(
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
    dbc_cache: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    store = PolicyStore(tmp_path / "policies")
    with engaged_on_the_shipped_policy(
        seeded_database_url, seeded_engine, tmp_path, dbc_cache, store
    ) as (r, small_sha256, assign_small):

        def full_card(sha256: str, content: bytes, actuation: object) -> Path:
            raise OSError(28, "No space left on device")

        # the SD card is full when the next policy arrives (before, the error escaped the
        # network pass and the car drove the old, no longer assigned policy)
        monkeypatch.setattr(store, "keep", full_card)
        assign_small()
        r.run(65.0, network=True, until=lambda: r.agent.stats.policies_not_kept > 0)
        assert r.agent.stats.policies_not_kept == 1
        assert r.agent.assignment is None
        r.run(1.0, network=True)
        assert r.agent.state.mode is not Mode.ENGAGED
        assert r.agent.status_report()["engage_reason"] == (
            "the assigned controller cannot run (its policy or parameters)"
        )
        # its status names no config it runs, beside no controller and no policy
        status = r.agent.status_report()
        assert "config_version" not in status
        assert "controller" not in status
        assert "policy_sha256" not in status
        # retried after 2, 4, 8, 16 s: 4 more tries in 31 s, not 15 every 2 s
        r.run(31.5, network=True)
        assert r.agent.stats.policies_not_kept == 5
        monkeypatch.undo()
        r.run(40.0, network=True, until=lambda: r.agent.assignment is not None)
        assert r.agent.assignment is not None
        assert r.agent.assignment.controller.policy_sha256 == small_sha256
