"""piStatus reports, a vehicle's config and the corridor geometry, over the real API."""

from __future__ import annotations

import gzip
import hashlib
import json
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text

from tests.support.api import serving
from tests.support.tokens import bearer, issue
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES

SEED_CORRIDOR = Path(__file__).resolve().parents[2] / "seed_data/i24_wb_corridor.json"


@pytest.fixture
def api(seeded_database_url: str) -> Iterator[httpx.Client]:
    with serving(seeded_database_url) as client:
        yield client


def statuses(engine: Engine) -> list[dict[str, Any]]:
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT * FROM fact_vehicle_status ORDER BY ts"))
        return [dict(row._mapping) for row in rows]


def report(**fields: Any) -> dict[str, Any]:
    return {"ts": datetime.now(UTC).replace(microsecond=0).isoformat(), **fields}


def test_a_status_report_is_stored_with_the_warehouse_names(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    body = report(
        agent_version="1.4.2",
        uptime_s=3600.5,
        can_ok=True,
        can_msgs_per_s=1450.0,
        gps_fix=True,
        gps_satellites=11,
        acc_available=True,
        controller="microaccel_acc",
        controller_running=False,
        plan_id=12,
        plan_age_s=14.0,
        spool_backlog=3,
        spool_dropped=1201,
        disk_free_mb=20480.0,
        cpu_temp_c=61.5,
        ups_on_battery=False,
        server_rtt_ms=85.0,
        engage_reason="no fresh plan",
    )
    answer = api.post("/api/v1/vehicles/SF-007/status", json=body, headers=car)

    assert answer.status_code == 200
    assert answer.json() == {"accepted": 1, "duplicates": 0}
    [row] = statuses(seeded_engine)
    assert row["vehicle_id"] == "SF-007"
    assert row["ts"].isoformat() == body["ts"]
    assert (row["is_can_ok"], row["has_gps_fix"], row["is_acc_available"]) == (True, True, True)
    assert (row["is_controller_running"], row["is_ups_on_battery"]) == (False, False)
    assert (row["agent_version"], row["gps_satellites"], row["spool_backlog"]) == ("1.4.2", 11, 3)
    assert row["cpu_temp_c"] == 61.5
    assert row["engage_reason"] == "no fresh plan"
    assert row["spool_dropped"] == 1201
    assert row["received_at"] is not None

    again = api.post("/api/v1/vehicles/SF-007/status", json=body, headers=car)
    assert again.json() == {"accepted": 0, "duplicates": 1}
    assert len(statuses(seeded_engine)) == 1


def test_only_ts_is_required(api: httpx.Client, seeded_engine: Engine) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    assert api.post("/api/v1/vehicles/SF-007/status", json=report(), headers=car).status_code == 200
    missing = api.post("/api/v1/vehicles/SF-007/status", json={"cpu_temp_c": 50}, headers=car)
    assert missing.status_code == 422


@pytest.mark.parametrize(
    ("fields", "status"),
    [
        ({"gps_satellites": 300}, 422),
        ({"disk_free_mb": -1}, 422),
        ({"ts": timedelta(minutes=10)}, 422),  # from now, when the test runs
        ({"ts": -timedelta(days=91)}, 422),
        ({"ts": "2026-11-23T09:00:00"}, 422),
    ],
    ids=["satellites", "disk", "future", "past-retention", "no-zone"],
)
def test_a_bad_status_report_is_422_and_not_stored(
    api: httpx.Client, seeded_engine: Engine, fields: dict[str, Any], status: int
) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    if isinstance(fields.get("ts"), timedelta):  # a time relative to the clock at run time
        fields = {**fields, "ts": (datetime.now(UTC) + fields["ts"]).isoformat()}
    answer = api.post("/api/v1/vehicles/SF-007/status", json=report(**fields), headers=car)
    assert answer.status_code == status
    assert statuses(seeded_engine) == []


def test_a_body_the_server_cannot_read_as_json_says_why(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    """curl's default form content type, or a gzip-compressed body, was answered "Input should
    be a valid dictionary" on a status, and "str is not valid UTF-8" on pings."""
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    body = json.dumps(report()).encode()
    form = api.post(
        "/api/v1/vehicles/SF-007/status",
        content=body,
        headers={**car, "Content-Type": "application/x-www-form-urlencoded"},
    )
    assert form.status_code == 422
    assert form.json()["detail"][0]["msg"] == (
        "the body must be JSON sent as Content-Type: application/json "
        "(not application/x-www-form-urlencoded)"
    )
    packed = gzip.compress(body)
    for path in ("/api/v1/vehicles/SF-007/status", "/api/v1/pings"):
        answer = api.post(
            path,
            content=packed,
            headers={**car, "Content-Type": "application/json", "Content-Encoding": "gzip"},
        )
        assert answer.status_code == 422, path
        assert "Content-Encoding gzip is not accepted; send the body uncompressed" in str(
            answer.json()["detail"]
        )
    assert statuses(seeded_engine) == []


def test_a_vehicle_token_reports_only_for_its_own_vehicle(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    answer = api.post("/api/v1/vehicles/SF-008/status", json=report(), headers=car)
    assert answer.status_code == 403
    assert statuses(seeded_engine) == []


def test_an_operator_reporting_for_an_unknown_vehicle_gets_404(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    operator = bearer(issue(seeded_engine, "operator"))
    answer = api.post("/api/v1/vehicles/SF-999/status", json=report(), headers=operator)
    assert answer.status_code == 404
    assert answer.json() == {"detail": "unknown vehicle SF-999"}


def test_a_vehicle_reads_its_config(api: httpx.Client, seeded_engine: Engine) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-098"))
    answer = api.get("/api/v1/vehicles/SF-098/config", headers=car)

    assert answer.status_code == 200
    config = answer.json()
    # seed_data/roster.csv: SF-098 is the first RAV4 (acceleration-actuated), route B, lane 2,
    # on rl_accel with the shipped policy, named by its sha256.
    assert (config["make"], config["model"], config["actuation"]) == ("Toyota", "RAV4", "accel")
    assert (config["corridor_id"], config["route"], config["assigned_lane"]) == ("I-24-WB", "B", 2)
    shipped = hashlib.sha256((BUNDLED_POLICIES / "rl_accel.npz").read_bytes()).hexdigest()
    assert config["controller"] == {"name": "rl_accel", "params": {"policy_sha256": shipped}}
    assert (config["active"], config["in_maintenance"]) == (True, False)
    assert config["ping_period_s"] == 1.0
    assert config["status_period_s"] == 10.0
    assert config["plan_poll_s"] == 5.0
    assert config["stale_plan_after_s"] == 180.0


@pytest.mark.parametrize(
    ("role", "vehicle", "path_vehicle", "status"),
    [
        ("vehicle", "SF-001", "SF-002", 403),
        ("feed", None, "SF-001", 403),
        ("viewer", None, "SF-001", 200),
        ("operator", None, "SF-999", 404),
    ],
)
def test_who_may_read_a_config(
    api: httpx.Client,
    seeded_engine: Engine,
    role: str,
    vehicle: str | None,
    path_vehicle: str,
    status: int,
) -> None:
    headers = bearer(issue(seeded_engine, role, vehicle))  # type: ignore[arg-type]
    assert api.get(f"/api/v1/vehicles/{path_vehicle}/config", headers=headers).status_code == status


def test_the_corridor_geometry_matches_the_seed(api: httpx.Client, seeded_engine: Engine) -> None:
    car = bearer(issue(seeded_engine, "vehicle", "SF-001"))
    answer = api.get("/api/v1/corridors/I-24-WB", headers=car)

    assert answer.status_code == 200
    corridor = answer.json()
    seed = json.loads(SEED_CORRIDOR.read_text())
    assert corridor["lanes"] == 4
    assert corridor["length_m"] == seed["corridor"]["length_m"]
    assert corridor["speed_limit_mps"] == pytest.approx(70 * 0.44704)
    assert [s["xd_code"] for s in corridor["inrix_segments"]] == [
        f"SF-I24WB-{column:02d}" for column in range(2, 20)
    ]
    assert len(corridor["segments"]) == len(seed["i24_segments"])
    first, last = corridor["segments"][0], corridor["segments"][-1]
    assert (first["start_x_m"], first["start_postmile"]) == (0.0, 0.0)
    assert last["end_x_m"] == seed["corridor"]["length_m"]
    # Consecutive sub-segments join end to start.
    assert all(
        a["end_x_m"] == b["start_x_m"]
        for a, b in zip(corridor["segments"], corridor["segments"][1:], strict=False)
    )

    unchanged = api.get(
        "/api/v1/corridors/I-24-WB", headers={**car, "If-None-Match": answer.headers["ETag"]}
    )
    assert unchanged.status_code == 304
    unknown = api.get("/api/v1/corridors/I-40-EB", headers=car)
    assert unknown.status_code == 404


def _wait_for_a_lock_wait(engine: Engine, timeout_s: float = 20.0) -> None:
    """Until a session of this database waits on a lock (the request, behind the delete)."""
    deadline = time.monotonic() + timeout_s
    with engine.connect() as watcher:
        while time.monotonic() < deadline:
            waiting = watcher.execute(
                text(
                    "SELECT count(*) FROM pg_stat_activity "
                    "WHERE datname = current_database() AND wait_event_type = 'Lock'"
                )
            ).scalar_one()
            if waiting:
                return
            watcher.rollback()
            time.sleep(0.02)
    raise AssertionError("the status request never waited for the vehicle's delete")


def test_a_vehicle_deleted_while_its_report_is_stored_is_404_not_500(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    """An operator deletes the car in SQL while its report is being stored: the report's insert
    cannot reference the row any more, which was a foreign-key violation and a 500."""
    operator = bearer(issue(seeded_engine, "operator"))
    with seeded_engine.connect() as deleting, ThreadPoolExecutor(1) as pool:
        deleting.execute(text("DELETE FROM dim_vehicle WHERE vehicle_id = 'SF-050'"))
        posted = pool.submit(
            api.post, "/api/v1/vehicles/SF-050/status", json=report(), headers=operator
        )
        _wait_for_a_lock_wait(seeded_engine)
        deleting.commit()
        answer = posted.result(timeout=30)

    assert answer.status_code == 404
    assert answer.json() == {"detail": "unknown vehicle SF-050"}
    assert statuses(seeded_engine) == []


def test_a_body_naming_a_key_twice_is_refused_on_every_data_endpoint(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    """A status, a ping, an INRIX snapshot or an operator's change with a key named twice was
    read by its last value and the sender never told; each is a 422 naming the key, and
    nothing is stored."""
    car = bearer(issue(seeded_engine, "vehicle", "SF-007"))
    stamp = report()["ts"]
    status = f'{{"ts": "{stamp}", "plan_age_s": 3.0, "plan_age_s": 900.0}}'
    answer = api.post(
        "/api/v1/vehicles/SF-007/status",
        content=status,
        headers={**car, "Content-Type": "application/json"},
    )
    assert answer.status_code == 422, answer.text
    [field] = answer.json()["detail"]
    assert field["type"] == "json_repeated_key"
    assert 'duplicate key "plan_age_s"' in field["msg"]
    assert statuses(seeded_engine) == []
    ping = (
        f'{{"vehicle_id": "SF-007", "ts": "{stamp}", "lat": 36.1, "lon": -86.7, '
        '"speed_mps": 20.0, "speed_mps": 7.5}'
    )
    answer = api.post(
        "/api/v1/pings", content=ping, headers={**car, "Content-Type": "application/json"}
    )
    assert answer.status_code == 422, answer.text
    assert 'duplicate key "speed_mps"' in answer.json()["detail"]
    feed = bearer(issue(seeded_engine, "feed"))
    snapshot = '{"docType": "GetSegmentSpeed", "result": {}, "result": {"segmentspeeds": []}}'
    answer = api.post(
        "/api/v1/feeds/inrix",
        content=snapshot,
        headers={**feed, "Content-Type": "application/json"},
    )
    assert answer.status_code == 422, answer.text
    assert answer.json()["detail"][0]["type"] == "json_repeated_key"
    operator = bearer(issue(seeded_engine, "operator"))
    change = '{"in_maintenance": true, "in_maintenance": false, "note": "tyres"}'
    answer = api.put(
        "/api/v1/vehicles/SF-007/maintenance",
        content=change,
        headers={**operator, "Content-Type": "application/json"},
    )
    assert answer.status_code == 422, answer.text
    assert 'duplicate key "in_maintenance"' in answer.json()["detail"][0]["msg"]
    # the same report without the repetition is taken
    clean = {"ts": stamp, "plan_age_s": 3.0}
    assert api.post("/api/v1/vehicles/SF-007/status", json=clean, headers=car).status_code == 200
    # only a JSON body an endpoint reads is checked: a GET's stray body is no business of it,
    # and a body sent as text is told it is not JSON, not that it repeats a key (a review)
    viewer = bearer(issue(seeded_engine, "viewer"))
    fleet = api.request("GET", "/api/v1/fleet", content='{"a": 1, "a": 2}', headers=viewer)
    assert fleet.status_code == 200, fleet.text
    as_text = api.post(
        "/api/v1/vehicles/SF-007/status",
        content=status,
        headers={**car, "Content-Type": "text/plain"},
    )
    assert as_text.status_code == 422
    assert as_text.json()["detail"][0]["type"] != "json_repeated_key"
