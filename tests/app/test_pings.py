"""POST /api/v1/pings against the real server and database: what vehicles rely on.

A 200 means the accepted rows are committed; a resent ping is a duplicate, never a second row;
bad pings are rejected one by one with their index and reason while the good ones are kept;
a vehicle token never stores another vehicle's pings.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text

from app.ingest.sql import SMALL_GROUP_ROWS
from tests.support.api import OFF_CORRIDOR, ON_CORRIDOR_X_M, fresh_ts, ping, serving
from tests.support.tokens import bearer, issue


@pytest.fixture
def api(seeded_database_url: str) -> Iterator[httpx.Client]:
    with serving(seeded_database_url) as client:
        yield client


@pytest.fixture
def car(seeded_engine: Engine) -> dict[str, str]:
    """Headers of SF-001's vehicle token."""
    return bearer(issue(seeded_engine, "vehicle", "SF-001"))


def stored(engine: Engine, vehicle_id: str = "SF-001") -> list[dict[str, Any]]:
    with engine.connect() as connection:
        rows = connection.execute(
            text("SELECT * FROM fact_vehicle_ping WHERE vehicle_id = :v ORDER BY ts"),
            {"v": vehicle_id},
        )
        return [dict(row._mapping) for row in rows]


def test_a_ping_is_committed_when_the_answer_arrives(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    ts = fresh_ts()
    body = ping(
        ts=ts,
        speed_mps=27.5,
        accel_mps2=-0.4,
        heading_deg=301.0,
        lane=2,
        acc_engaged=True,
        controller_engaged=False,
        controller="microaccel_acc",
        acc_speed_setting_mph=62,
        acc_gap_setting=3,
        lead_present=True,
        lead_distance_m=41.5,
        lead_rel_speed_mps=-1.25,
        plan_id=77,
    )
    before = datetime.now(UTC)
    answer = api.post("/api/v1/pings", json=body, headers=car)
    after = datetime.now(UTC)

    assert answer.status_code == 200
    assert answer.json() == {"accepted": 1, "duplicates": 0, "conflicts": 0, "rejected": []}
    [row] = stored(seeded_engine)  # read right after the answer: already committed
    assert row["ts"] == ts
    assert before <= row["received_at"] <= after
    assert row["speed_mps"] == 27.5
    assert row["accel_mps2"] == pytest.approx(-0.4)  # stored as real (float4)
    assert row["heading_deg"] == 301.0
    assert row["lane"] == 2
    assert row["is_acc_engaged"] is True
    assert row["is_controller_engaged"] is False
    assert row["controller"] == "microaccel_acc"
    assert row["acc_speed_setting_mph"] == 62
    assert row["acc_gap_setting"] == 3
    assert row["is_lead_present"] is True
    assert row["lead_distance_m"] == pytest.approx(41.5)
    assert row["lead_rel_speed_mps"] == pytest.approx(-1.25)
    assert row["plan_id"] == 77


def test_the_position_along_the_corridor_is_map_matched_at_ingest(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    on, off = ping(), ping(**OFF_CORRIDOR)
    answer = api.post("/api/v1/pings", json={"pings": [on, off]}, headers=car)

    assert answer.json()["accepted"] == 2
    by_ts = {row["ts"].isoformat(): row["x_m"] for row in stored(seeded_engine)}
    # The fix is a vertex of the corridor's polyline: its x_m is that vertex's x_m.
    assert by_ts[on["ts"]] == pytest.approx(ON_CORRIDOR_X_M, abs=0.5)
    assert by_ts[off["ts"]] is None


def test_a_ping_driving_against_the_corridor_is_stored_off_it(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    # Westbound I-24 runs north-west here (about 323 degrees); the other carriageway south-east.
    along, against = ping(heading_deg=323.0), ping(heading_deg=143.0)
    slow_against = ping(heading_deg=143.0, speed_mps=0.5)  # a stopped car's heading is noise
    answer = api.post("/api/v1/pings", json={"pings": [along, against, slow_against]}, headers=car)

    assert answer.json()["accepted"] == 3
    by_ts = {row["ts"].isoformat(): row["x_m"] for row in stored(seeded_engine)}
    assert by_ts[along["ts"]] == pytest.approx(ON_CORRIDOR_X_M, abs=0.5)
    assert by_ts[against["ts"]] is None
    assert by_ts[slow_against["ts"]] == pytest.approx(ON_CORRIDOR_X_M, abs=0.5)


def test_a_resent_ping_is_a_duplicate_never_a_second_row(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    first, second = ping(), ping()
    answer = api.post("/api/v1/pings", json={"pings": [first, second, first]}, headers=car)
    assert answer.json() == {"accepted": 2, "duplicates": 1, "conflicts": 0, "rejected": []}

    again = api.post("/api/v1/pings", json={"pings": [second, first]}, headers=car)
    assert again.json() == {"accepted": 0, "duplicates": 2, "conflicts": 0, "rejected": []}
    assert len(stored(seeded_engine)) == 2


@pytest.mark.parametrize(
    "size", [1, SMALL_GROUP_ROWS, SMALL_GROUP_ROWS + 1], ids=["one", "one-statement", "copy"]
)
def test_both_ways_of_writing_a_group_store_the_same_row_and_find_the_resent(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine, size: int
) -> None:
    """A small group is one INSERT statement, a large one a COPY: what they store is the same,
    a value too small for a REAL is 0 in both, and both tell resent pings from new ones."""
    fields = {
        "speed_mps": 27.5,
        "accel_mps2": 1e-300,
        "heading_deg": 301.0,
        "lane": 2,
        "acc_engaged": True,
        "controller_engaged": False,
        "controller": "microaccel_acc",
        "acc_speed_setting_mph": 62,
        "acc_gap_setting": 3,
        "lead_present": True,
        "lead_distance_m": 41.5,
        "lead_rel_speed_mps": -1.25,
        "plan_id": None,
    }
    first = ping(**fields)
    assert api.post("/api/v1/pings", json=first, headers=car).json()["accepted"] == 1
    batch = [first, *(ping(**fields) for _ in range(size - 1))]

    answer = api.post("/api/v1/pings", json={"pings": batch}, headers=car)

    assert answer.json() == {"accepted": size - 1, "duplicates": 1, "conflicts": 0, "rejected": []}
    rows = stored(seeded_engine)
    assert len(rows) == size
    expected = {**fields, "accel_mps2": 0.0}
    for row in rows:
        assert row["x_m"] is not None
        assert {
            "speed_mps": row["speed_mps"],
            "accel_mps2": row["accel_mps2"],
            "heading_deg": row["heading_deg"],
            "lane": row["lane"],
            "acc_engaged": row["is_acc_engaged"],
            "controller_engaged": row["is_controller_engaged"],
            "controller": row["controller"],
            "acc_speed_setting_mph": row["acc_speed_setting_mph"],
            "acc_gap_setting": row["acc_gap_setting"],
            "lead_present": row["is_lead_present"],
            "lead_distance_m": row["lead_distance_m"],
            "lead_rel_speed_mps": row["lead_rel_speed_mps"],
            "plan_id": row["plan_id"],
        } == expected


@pytest.mark.parametrize("size", [1, SMALL_GROUP_ROWS + 1], ids=["one-statement", "copy"])
def test_a_resend_saying_something_else_is_a_conflict_logged_and_the_first_kept(
    api: httpx.Client,
    car: dict[str, str],
    seeded_engine: Engine,
    size: int,
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A ping at a stored (vehicle_id, ts) with other content was counted as a plain duplicate
    and dropped without a word: a car whose clock repeats a second lost pings unseen. Values a
    REAL rounds (0.12) must not make an identical resend read as a conflict."""
    first = ping(speed_mps=24.5, accel_mps2=0.12, lead_distance_m=35.1)
    assert api.post("/api/v1/pings", json=first, headers=car).json()["accepted"] == 1
    other = {**first, "speed_mps": 3.0}
    extra = [ping() for _ in range(size - 1)]

    with caplog.at_level(logging.WARNING, logger="app.ingest.service"):
        resent = api.post("/api/v1/pings", json={"pings": [first, *extra]}, headers=car).json()
        clashing = api.post("/api/v1/pings", json={"pings": [other, *extra]}, headers=car).json()

    assert (resent["accepted"], resent["duplicates"], resent["conflicts"]) == (size - 1, 1, 0)
    assert (clashing["accepted"], clashing["duplicates"], clashing["conflicts"]) == (0, size, 1)
    [kept] = [
        row for row in stored(seeded_engine) if row["ts"] == datetime.fromisoformat(first["ts"])
    ]
    assert kept["speed_mps"] == 24.5
    [warning] = [r.getMessage() for r in caplog.records if "already stored" in r.getMessage()]
    assert warning.startswith("vehicle SF-001 sent 1 ping(s) at a ts already stored with other")


def test_two_pings_at_one_ts_in_one_batch_are_a_conflict_the_first_stored(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    first = ping(speed_mps=20.0)
    same, other = dict(first), {**first, "lane": 3}

    answer = api.post("/api/v1/pings", json={"pings": [first, same, other]}, headers=car)

    assert answer.json() == {"accepted": 1, "duplicates": 2, "conflicts": 1, "rejected": []}
    [row] = stored(seeded_engine)
    assert row["lane"] is None


def test_the_same_ping_in_concurrent_requests_is_stored_once_and_counted_everywhere(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    shared = ping()
    requests = 24

    def post(_: int) -> dict[str, Any]:
        body = {"pings": [shared, ping()]}
        answer: dict[str, Any] = api.post("/api/v1/pings", json=body, headers=car).json()
        return answer

    with ThreadPoolExecutor(max_workers=12) as pool:
        answers = list(pool.map(post, range(requests)))

    assert sum(a["accepted"] for a in answers) == requests + 1
    assert sum(a["duplicates"] for a in answers) == requests - 1
    assert len(stored(seeded_engine)) == requests + 1


def test_bad_pings_are_rejected_one_by_one_and_the_good_ones_kept(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine, seeded_database_url: str
) -> None:
    admin = bearer(issue(seeded_engine, "admin"))
    now = datetime.now(UTC)
    good = [ping(), ping(), ping()]
    batch = [
        good[0],
        ping(speed_mps=-0.1),
        ping(speed_mps=90.5),
        ping(lat=91.0),
        ping(lon=-180.5),
        ping(lane=5),  # I-24-WB has 4 lanes
        ping(acc_gap_setting=4),
        ping(ts=(now + timedelta(minutes=6)).isoformat()),
        ping(ts=(now - timedelta(days=91)).isoformat()),
        ping(vehicle_id="SF-999"),
        good[1],
        "not a ping",
        {k: v for k, v in ping().items() if k != "speed_mps"},
        ping(ts="2026-11-23T10:00:00"),  # no zone
        good[2],
    ]
    answer = api.post("/api/v1/pings", json={"pings": batch}, headers=admin)

    assert answer.status_code == 200
    body = answer.json()
    assert (body["accepted"], body["duplicates"]) == (3, 0)
    reasons = {r["index"]: r["error"] for r in body["rejected"]}
    assert sorted(reasons) == [1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13]
    assert reasons[1].startswith("speed_mps:")
    assert reasons[2].startswith("speed_mps:")
    assert reasons[3].startswith("lat:")
    assert reasons[4].startswith("lon:")
    assert reasons[5] == "lane 5 is outside the 4 lanes of I-24-WB"
    assert reasons[6].startswith("acc_gap_setting:")
    assert reasons[7] == "ts is more than 300 s in the future"
    assert reasons[8] == "ts is older than the 90-day retention window"
    assert reasons[9] == "unknown vehicle SF-999"
    assert reasons[11] == "a ping must be a JSON object"
    assert reasons[12] == "speed_mps: Field required"
    assert reasons[13].startswith("ts:")
    assert "timezone" in reasons[13]
    # what the same ping may pass later (the server's clock or roster behind) says so
    retryable = {r["index"] for r in body["rejected"] if r["retryable"]}
    assert retryable == {7, 9}
    assert {row["ts"].isoformat() for row in stored(seeded_engine)} == {p["ts"] for p in good}


def test_a_vehicle_token_posting_another_vehicles_ping_stores_nothing(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    batch = {"pings": [ping(), ping(vehicle_id="SF-002"), ping()]}
    answer = api.post("/api/v1/pings", json=batch, headers=car)

    assert answer.status_code == 403
    assert "SF-001" in answer.json()["detail"]
    assert "SF-002" in answer.json()["detail"]
    assert stored(seeded_engine, "SF-001") == []
    assert stored(seeded_engine, "SF-002") == []


@pytest.mark.parametrize(("role", "status"), [("operator", 200), ("viewer", 403), ("feed", 403)])
def test_which_ops_tokens_may_post_pings(
    api: httpx.Client, seeded_engine: Engine, role: str, status: int
) -> None:
    headers = bearer(issue(seeded_engine, role))  # type: ignore[arg-type]
    answer = api.post("/api/v1/pings", json=ping(vehicle_id="SF-042"), headers=headers)
    assert answer.status_code == status
    assert len(stored(seeded_engine, "SF-042")) == (1 if status == 200 else 0)


@pytest.mark.parametrize(
    "headers",
    [{}, {"Authorization": "Bearer sf_not-a-token"}, {"Authorization": "Basic dXNlcjpwdw=="}],
    ids=["missing", "unknown", "not-bearer"],
)
def test_without_a_valid_token_nothing_is_stored(
    api: httpx.Client, seeded_engine: Engine, headers: dict[str, str]
) -> None:
    answer = api.post("/api/v1/pings", json=ping(), headers=headers)
    assert answer.status_code == 401
    assert answer.headers["WWW-Authenticate"] == "Bearer"
    assert answer.json()["detail"]
    assert stored(seeded_engine) == []


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        (b"{not json", "body is not JSON"),
        (b"[1, 2]", "body must be a ping object"),
        (b'{"hello": "world"}', "body is neither a ping"),
        (b'{"pings": {"vehicle_id": "SF-001"}}', '"pings" must be a list'),
    ],
)
def test_a_body_that_is_not_a_ping_or_a_batch_is_422(
    api: httpx.Client, car: dict[str, str], content: bytes, expected: str
) -> None:
    headers = {**car, "Content-Type": "application/json"}
    answer = api.post("/api/v1/pings", content=content, headers=headers)
    assert answer.status_code == 422
    assert answer.json()["detail"].startswith(expected)


def test_a_body_that_is_both_a_ping_and_a_batch_is_422_naming_both(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    """A ping with a list of pings beside its fields was read as the batch: 200, the ping's own
    fields dropped and nothing stored (audit)."""
    answer = api.post("/api/v1/pings", json=ping(pings=[]), headers=car)
    assert (answer.status_code, answer.json()["detail"]) == (
        422,
        'body is both a ping (it has vehicle_id, ts, lat, lon, speed_mps) and a batch ("pings": '
        "[...]): send the ping alone or inside the batch",
    )
    assert stored(seeded_engine) == []


def test_a_lone_ping_with_an_unknown_field_called_pings_is_stored(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    """A ping ignores fields it does not know, but one named "pings" made the body read as a
    batch, refused whole with 422: the ping was lost for good."""
    answer = api.post("/api/v1/pings", json=ping(pings="from a newer agent"), headers=car)
    assert answer.status_code == 200, answer.text
    assert answer.json()["accepted"] == 1
    assert len(stored(seeded_engine)) == 1
    # a body that is only {"pings": <not a list>} is still no batch at all
    bad = api.post("/api/v1/pings", json={"pings": "x"}, headers=car)
    assert (bad.status_code, bad.json()["detail"]) == (
        422,
        '"pings" must be a list of ping objects',
    )


def test_a_batch_of_1000_fits_and_1001_is_refused_whole(
    api: httpx.Client, car: dict[str, str], seeded_engine: Engine
) -> None:
    start = datetime.now(UTC).replace(microsecond=0) - timedelta(hours=2)
    batch = [ping(ts=start + timedelta(seconds=k), lane=1 + k % 4) for k in range(1001)]

    too_many = api.post("/api/v1/pings", json={"pings": batch}, headers=car)
    assert too_many.status_code == 422
    assert "at most 1000" in too_many.json()["detail"]

    answer = api.post("/api/v1/pings", json={"pings": batch[:1000]}, headers=car)
    assert answer.json() == {"accepted": 1000, "duplicates": 0, "conflicts": 0, "rejected": []}
    assert len(stored(seeded_engine)) == 1000


def test_a_body_over_the_limit_is_413_declared_or_streamed(
    seeded_database_url: str, car: dict[str, str], seeded_engine: Engine
) -> None:
    batch = {"pings": [ping() for _ in range(40)]}
    with serving(seeded_database_url, max_body_bytes=4096) as client:
        declared = client.post("/api/v1/pings", json=batch, headers=car)

        def chunks() -> Iterator[bytes]:
            yield b'{"pings": ['
            for _ in range(100):
                yield b'{"vehicle_id": "SF-001", "ts": "2026-01-01T00:00:00Z"},'
            yield b"]}"

        streamed = client.post(
            "/api/v1/pings",
            content=chunks(),
            headers={**car, "Content-Type": "application/json"},
        )
    assert declared.status_code == 413
    assert declared.json()["detail"] == "request body over the limit of 4096 bytes"
    assert streamed.status_code == 413
    assert stored(seeded_engine) == []


def test_a_streamed_body_over_the_limit_is_413_on_every_route(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """FastAPI wraps what stops it reading a body in its own 400, which the API answers 422
    ("not valid JSON"): a car or feed told its too-large upload was malformed content."""
    admin = bearer(issue(seeded_engine, "admin"))

    def chunks() -> Iterator[bytes]:
        yield b'{"ts": "2026-01-01T00:00:00Z", "padding": "'
        for _ in range(100):
            yield b"x" * 100
        yield b'"}'

    with serving(seeded_database_url, max_body_bytes=4096) as client:
        for path in ("/api/v1/vehicles/SF-001/status", "/api/v1/feeds/inrix"):
            answer = client.post(
                path, content=chunks(), headers={**admin, "Content-Type": "application/json"}
            )
            assert answer.status_code == 413, (path, answer.text)
            assert answer.json()["detail"] == "request body over the limit of 4096 bytes"


def test_counters_count_accepted_duplicate_and_rejected_pings(
    api: httpx.Client, car: dict[str, str]
) -> None:
    def counters() -> dict[str, float]:
        found = {}
        for line in api.get("/metrics").text.splitlines():
            if line.startswith("smoothfleet_pings_total{"):
                name, value = line.rsplit(" ", 1)
                found[name.split('"')[1]] = float(value)
        return found

    before = counters()
    first = ping()
    api.post("/api/v1/pings", json={"pings": [first, first, ping(speed_mps=-1)]}, headers=car)
    after = counters()

    assert after["accepted"] - before.get("accepted", 0) == 1
    assert after["duplicate"] - before.get("duplicate", 0) == 1
    assert after["rejected"] - before.get("rejected", 0) == 1
    latency = api.get("/metrics").text
    assert (
        'smoothfleet_http_request_duration_seconds_count{method="POST",route="/api/v1/pings"'
        in (latency)
    )


def test_a_database_outage_is_503_with_retry_after(
    seeded_database_url: str, seeded_engine: Engine, pg_server: str
) -> None:
    from psycopg import sql
    from sqlalchemy.engine import make_url

    from tests.support.databases import admin_execute

    token = bearer(issue(seeded_engine, "vehicle", "SF-001"))
    with serving(seeded_database_url) as client:
        assert client.post("/api/v1/pings", json=ping(), headers=token).status_code == 200
        name = make_url(seeded_database_url).database
        seeded_engine.dispose()
        admin_execute(
            pg_server, sql.SQL("DROP DATABASE {} WITH (FORCE)").format(sql.Identifier(name))
        )
        answer = client.post("/api/v1/pings", json=ping(), headers=token)
    assert answer.status_code == 503
    assert answer.headers["Retry-After"] == "5"
    assert answer.json() == {
        "detail": "database unavailable, retry later",
        "code": "database_unavailable",
    }


def test_pings_of_a_vehicle_just_removed_from_the_roster_are_rejected_per_item(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    operator = bearer(issue(seeded_engine, "operator"))
    assert api.post("/api/v1/pings", json=ping("SF-050"), headers=operator).status_code == 200
    with seeded_engine.begin() as connection:  # removed while the server still caches it
        connection.execute(text("DELETE FROM fact_vehicle_ping WHERE vehicle_id = 'SF-050'"))
        connection.execute(text("DELETE FROM dim_vehicle WHERE vehicle_id = 'SF-050'"))

    answer = api.post(
        "/api/v1/pings", json={"pings": [ping("SF-051"), ping("SF-050")]}, headers=operator
    )

    assert answer.status_code == 200
    assert answer.json() == {
        "accepted": 1,
        "duplicates": 0,
        "conflicts": 0,
        # retryable: put back on the roster, the car's pings are taken then
        "rejected": [{"index": 1, "error": "unknown vehicle SF-050", "retryable": True}],
    }
    assert len(stored(seeded_engine, "SF-051")) == 1


def test_a_ping_older_than_retention_is_refused_for_good_even_from_an_unknown_vehicle(
    api: httpx.Client, seeded_engine: Engine
) -> None:
    """The roster was checked first, so it was "unknown vehicle", retryable: a ping the server
    can never take, resent with every batch while the car kept it."""
    operator = bearer(issue(seeded_engine, "operator"))
    old = (datetime.now(UTC) - timedelta(days=91)).isoformat()
    answer = api.post("/api/v1/pings", json={"pings": [ping("SF-999", ts=old)]}, headers=operator)
    assert answer.json()["rejected"] == [
        {"index": 0, "error": "ts is older than the 90-day retention window", "retryable": False}
    ]


def test_the_endpoint_is_documented_with_its_body_and_security(api: httpx.Client) -> None:
    operation = api.get("/openapi.json").json()["paths"]["/api/v1/pings"]["post"]
    body = operation["requestBody"]["content"]["application/json"]["schema"]
    ping_schema, batch_schema = body["anyOf"]
    assert set(ping_schema["required"]) == {"vehicle_id", "ts", "lat", "lon", "speed_mps"}
    assert batch_schema["properties"]["pings"]["maxItems"] == 1000
    assert operation["security"] == [{"HTTPBearer": []}]
    assert {"200", "401", "403", "413", "422", "503"} <= set(operation["responses"])
