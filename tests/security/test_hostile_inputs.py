"""Hostile JSON at every message the API takes: never a 5xx, never a traceback in the log, and
everything acknowledged is in the warehouse.

First the inputs that once got 500s or were stored although meaningless (named cases), then
hypothesis: a valid message of each type with fields replaced by hostile values (NUL, lone
surrogates, NaN and Infinity literals, 1e999, huge and tiny numbers, wrong types, impossible
timestamps), written as raw JSON text the way a careless or malicious client would.
"""

from __future__ import annotations

import itertools
import json
import logging
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import Engine, text

from tests.support.api import ON_CORRIDOR, serving
from tests.support.fleet import healthy_status
from tests.support.tokens import bearer, issue

NOW = datetime.now(UTC).replace(microsecond=0)
INRIX_CODE = "SF-I24WB-11"
# Placeholders replaced in the JSON text by literals json.dumps cannot write.
_LITERALS = {
    "__1E999__": "1e999",
    "__-1E999__": "-1e999",
    "__TINY__": "1e-320",
    "__5000_DIGITS__": "9" * 5000,  # past Python's integer text limit (4,300 digits)
}
_ts = itertools.count(1)


def raw_json(value: Any) -> bytes:
    """JSON text with NaN/Infinity literals, escaped lone surrogates and overflowing numbers."""
    text_ = json.dumps(value, allow_nan=True)  # ensure_ascii: a surrogate becomes \\ud800
    for placeholder, literal in _LITERALS.items():
        text_ = text_.replace(f'"{placeholder}"', literal)
    return text_.encode()


def fresh_ts() -> str:
    return (NOW - timedelta(seconds=next(_ts))).isoformat()


class ServerLog(logging.Handler):
    """Every record the in-process server logs at ERROR or with a traceback."""

    def __init__(self) -> None:
        super().__init__(logging.DEBUG)
        self.bad: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno >= logging.ERROR or record.exc_info:
            self.bad.append(f"{record.name}: {record.getMessage()}")


@pytest.fixture
def server_log() -> Iterator[ServerLog]:
    handler = ServerLog()
    logging.getLogger().addHandler(handler)
    try:
        yield handler
    finally:
        logging.getLogger().removeHandler(handler)


@pytest.fixture
def api(seeded_database_url: str, server_log: ServerLog) -> Iterator[httpx.Client]:
    with serving(
        seeded_database_url, planner_enabled=False, rate_limit_per_token_per_s=0
    ) as client:
        yield client
    assert not server_log.bad, server_log.bad[:5]


@pytest.fixture
def admin(seeded_engine: Engine) -> dict[str, str]:
    return bearer(issue(seeded_engine, "admin"))


def post(client: httpx.Client, path: str, body: bytes, headers: dict[str, str]) -> httpx.Response:
    answer = client.post(
        path, content=body, headers={**headers, "content-type": "application/json"}
    )
    assert answer.status_code < 500, (answer.status_code, answer.text, body[:300])
    answer.json()  # always a JSON body
    return answer


def a_ping(**fields: Any) -> dict[str, Any]:
    return {"vehicle_id": "SF-001", "ts": fresh_ts(), **ON_CORRIDOR, "speed_mps": 24.5, **fields}


def an_inrix(measured_at: str, **segment: Any) -> dict[str, Any]:
    reading = {"code": INRIX_CODE, "type": "XDS", "speed": 55.0, "score": 30, **segment}
    return {"result": {"segmentspeeds": [{"timestamp": measured_at, "segments": [reading]}]}}


def a_status(**fields: Any) -> dict[str, Any]:
    report = healthy_status(NOW, **fields)
    report["ts"] = fields.get("ts", fresh_ts())
    return report


# --- the named cases --------------------------------------------------------------------------

NON_FINITE = [float("nan"), float("inf"), float("-inf"), "__1E999__", "__-1E999__"]


@pytest.mark.parametrize("value", NON_FINITE, ids=["nan", "inf", "-inf", "1e999", "-1e999"])
def test_a_non_finite_status_number_is_422_naming_it(
    api: httpx.Client, admin: dict[str, str], value: Any
) -> None:
    answer = post(
        api, "/api/v1/vehicles/SF-001/status", raw_json(a_status(cpu_temp_c=value)), admin
    )
    assert answer.status_code == 422
    assert answer.json()["detail"][0]["loc"] == ["body", "cpu_temp_c"]


@pytest.mark.parametrize("value", NON_FINITE, ids=["nan", "inf", "-inf", "1e999", "-1e999"])
def test_a_non_finite_inrix_speed_is_refused_naming_it(
    api: httpx.Client, admin: dict[str, str], value: Any
) -> None:
    body = raw_json(an_inrix(fresh_ts(), speed=value))
    answer = post(api, "/api/v1/feeds/inrix", body, admin)
    assert answer.status_code == 200
    (refused,) = answer.json()["refused"]
    assert refused["error"].startswith("speed: ")
    assert answer.json()["accepted"] == 0


@pytest.mark.parametrize(
    ("field", "value"),
    [("agent_version", "1.0\ud800"), ("controller", "a\x00b")],
    ids=["lone-surrogate", "nul"],
)
def test_text_postgresql_cannot_store_is_422_naming_the_field(
    api: httpx.Client, admin: dict[str, str], field: str, value: str
) -> None:
    answer = post(
        api, "/api/v1/vehicles/SF-001/status", raw_json(a_status(**{field: value})), admin
    )
    assert answer.status_code == 422
    assert answer.json()["detail"][0]["loc"] == ["body", field]


def test_a_status_with_an_integer_too_long_to_read_is_422_saying_so(
    api: httpx.Client, admin: dict[str, str]
) -> None:
    """The text is JSON; Python refuses to read an integer of over 4,300 digits. The answer
    said "request body is not valid JSON text" (audit)."""
    answer = post(
        api,
        "/api/v1/vehicles/SF-001/status",
        raw_json(a_status(gps_satellites="__5000_DIGITS__")),
        admin,
    )
    assert answer.status_code == 422
    assert "integer too long to read" in answer.json()["detail"]


@pytest.mark.parametrize(
    ("url", "loc"),
    [
        ("/api/v1/plans/latest?corridor=I-24%00WB", ["query", "corridor"]),
        ("/api/v1/plans?corridor=I-24%00WB", ["query", "corridor"]),
        ("/api/v1/fleet?route=A%00", ["query", "route"]),
        ("/api/v1/fleet?make=Toyota%00", ["query", "make"]),
        ("/api/v1/corridors/I-24%00WB", ["path", "corridor_id"]),
    ],
    ids=["plan", "plan-runs", "fleet-route", "fleet-make", "corridor"],
)
def test_a_read_naming_text_postgresql_cannot_hold_is_422_naming_the_parameter(
    api: httpx.Client, admin: dict[str, str], url: str, loc: list[str]
) -> None:
    """Such a read reached the database and came back as "a value cannot be stored", naming
    neither the parameter nor a read (audit)."""
    answer = api.get(url, headers=admin)
    assert answer.status_code == 422, answer.text
    assert answer.json()["detail"][0]["loc"] == loc


def test_in_a_batch_a_nan_literal_or_unstorable_text_rejects_only_its_ping(
    api: httpx.Client, admin: dict[str, str], seeded_engine: Engine
) -> None:
    batch = [
        a_ping(),
        a_ping(speed_mps=float("nan")),
        a_ping(controller="a\x00b"),
        a_ping(controller="x\udc00"),
        a_ping(lead_distance_m="__1E999__"),
        a_ping(plan_id="__5000_DIGITS__"),
        a_ping(),
    ]
    answer = post(api, "/api/v1/pings", raw_json({"pings": batch}), admin)
    assert answer.status_code == 200
    result = answer.json()
    assert result["accepted"] == 2
    assert [(r["index"], r["error"].split(":")[0]) for r in result["rejected"]] == [
        (1, "speed_mps"),
        (2, "controller"),
        (3, "controller"),
        (4, "lead_distance_m"),
        (5, "plan_id"),
    ]
    with seeded_engine.connect() as connection:
        stored = connection.execute(text("SELECT count(*) FROM fact_vehicle_ping")).scalar_one()
    assert stored == 2


@pytest.mark.parametrize(
    "measured_at",
    ["2099-01-01T00:00:00Z", "0001-01-01T00:00:00+05:00", "1999-06-01T12:00:00Z"],
    ids=["2099", "year-1-bc-in-utc", "long-ago"],
)
def test_an_inrix_snapshot_from_an_impossible_time_is_refused_and_not_stored(
    api: httpx.Client, admin: dict[str, str], seeded_engine: Engine, measured_at: str
) -> None:
    """A time outside the window refuses the snapshot (422); one that is no time at all (year
    0 once in UTC) is its set's timestamp unreadable, and the set is refused on its own (since
    2026-12-05: a broken set no longer costs the others)."""
    answer = post(api, "/api/v1/feeds/inrix", raw_json(an_inrix(measured_at)), admin)
    if measured_at.startswith("0001"):
        assert answer.status_code == 200
        [refused] = answer.json()["refused"]
        assert (refused["segment_set"], refused["segment"]) == (0, None)
        assert refused["error"].startswith("timestamp: ")
    else:
        assert answer.status_code == 422
    with seeded_engine.connect() as connection:
        assert connection.execute(text("SELECT count(*) FROM fact_inrix_estimate")).scalar() == 0


def test_validation_errors_have_one_shape_without_echoing_the_input(
    api: httpx.Client, admin: dict[str, str]
) -> None:
    answer = post(api, "/api/v1/vehicles/SF-001/status", b'{"ts": "soon", "uptime_s": -1}', admin)
    assert answer.status_code == 422
    assert answer.json() == {
        "detail": [
            {
                "loc": ["body", "ts"],
                "msg": "Input should be a valid datetime or date, input is too short",
                "type": "datetime_from_date_parsing",
            },
            {
                "loc": ["body", "uptime_s"],
                "msg": "Input should be greater than or equal to 0",
                "type": "greater_than_equal",
            },
        ]
    }


# --- hypothesis: hostile values in every field ----------------------------------------------

hostile_scalars = st.one_of(
    st.sampled_from(
        [
            float("nan"),
            float("inf"),
            float("-inf"),
            "__1E999__",
            "__-1E999__",
            "__TINY__",
            1e300,
            -1e300,
            2**63,
            -(2**63) - 1,
            10**30,
            "",
            "\x00",
            "a\x00",
            "\ud800",
            "x\udfff",
            "\u2028",
            "0001-01-01T00:00:00+05:00",
            "9999-12-31T23:59:59-05:00",
            "2099-01-01T00:00:00Z",
            "1969-12-31T23:59:59Z",
            "2026-11-30T12:00:00",
            True,
            None,
            [],
            {},
            "x" * 10_000,
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(),
    st.text(max_size=20),
)
PING_FIELDS = [
    "vehicle_id", "ts", "lat", "lon", "speed_mps", "accel_mps2", "heading_deg", "lane",
    "acc_engaged", "controller_engaged", "controller", "acc_speed_setting_mph",
    "acc_gap_setting", "lead_present", "lead_distance_m", "lead_rel_speed_mps", "plan_id",
]  # fmt: skip
STATUS_FIELDS = list(healthy_status(NOW))
INRIX_FIELDS = [
    "code", "type", "speed", "average", "reference", "travelTimeMinutes", "score", "c-Value",
    "segmentClosed",
]  # fmt: skip
HYPOTHESIS = settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)


def spoiled(fields: list[str]) -> st.SearchStrategy[dict[str, Any]]:
    """Some fields replaced by hostile values."""
    return st.dictionaries(st.sampled_from(fields), hostile_scalars, min_size=1, max_size=3)


def stored_pings(engine: Engine) -> set[tuple[str, str]]:
    with engine.connect() as connection:
        rows = connection.execute(text("SELECT vehicle_id, ts FROM fact_vehicle_ping")).all()
    return {(vehicle, ts.isoformat()) for vehicle, ts in rows}


@pytest.mark.slow
@HYPOTHESIS
@given(changes=st.lists(spoiled(PING_FIELDS), min_size=1, max_size=4))
def test_hostile_pings_never_5xx_and_what_is_acknowledged_is_stored(
    api: httpx.Client, admin: dict[str, str], seeded_engine: Engine, changes: list[dict[str, Any]]
) -> None:
    batch = [a_ping(), *(a_ping(**change) for change in changes)]
    answer = post(api, "/api/v1/pings", raw_json({"pings": batch}), admin)
    if answer.status_code != 200:
        assert answer.status_code in (403, 422), answer.text
        return
    result = answer.json()
    rejected = {r["index"] for r in result["rejected"]}
    accepted = [
        (ping["vehicle_id"], datetime.fromisoformat(ping["ts"]).astimezone(UTC).isoformat())
        for index, ping in enumerate(batch)
        if index not in rejected
    ]
    assert result["accepted"] + result["duplicates"] == len(accepted)
    assert set(accepted) <= stored_pings(seeded_engine)


@pytest.mark.slow
@HYPOTHESIS
@given(change=spoiled(STATUS_FIELDS))
def test_hostile_status_reports_never_5xx_and_what_is_acknowledged_is_stored(
    api: httpx.Client, admin: dict[str, str], seeded_engine: Engine, change: dict[str, Any]
) -> None:
    report = {**a_status(), **change}
    answer = post(api, "/api/v1/vehicles/SF-001/status", raw_json(report), admin)
    if answer.status_code != 200:
        assert answer.status_code == 422, answer.text
        return
    if answer.json()["accepted"]:
        ts = datetime.fromisoformat(report["ts"])
        with seeded_engine.connect() as connection:
            found = connection.execute(
                text("SELECT count(*) FROM fact_vehicle_status WHERE vehicle_id = 'SF-001' "
                     "AND ts = :ts"),
                {"ts": ts if ts.tzinfo else ts.replace(tzinfo=UTC)},
            ).scalar_one()  # fmt: skip
        assert found == 1


@pytest.mark.slow
@HYPOTHESIS
@given(change=spoiled(INRIX_FIELDS), timestamp=st.one_of(st.just(None), hostile_scalars))
def test_hostile_inrix_snapshots_never_5xx_and_what_is_acknowledged_is_stored(
    api: httpx.Client,
    admin: dict[str, str],
    seeded_engine: Engine,
    change: dict[str, Any],
    timestamp: Any,
) -> None:
    document = an_inrix(fresh_ts() if timestamp is None else timestamp, **change)
    answer = post(api, "/api/v1/feeds/inrix", raw_json(document), admin)
    if answer.status_code != 200:
        assert answer.status_code == 422, answer.text
        return
    result = answer.json()
    with seeded_engine.connect() as connection:
        found = connection.execute(
            text("SELECT count(*) FROM fact_inrix_estimate WHERE measured_at = ANY(:at)"),
            {"at": [datetime.fromisoformat(moment) for moment in result["measured_at"]]},
        ).scalar_one()
    assert found >= result["accepted"]


@pytest.mark.slow
@HYPOTHESIS
@given(
    lane=hostile_scalars,
    route=hostile_scalars,
    name=st.one_of(st.just("microaccel_acc"), hostile_scalars),
    params=st.dictionaries(st.sampled_from(["gain", "v_des", "headway_s", "x"]), hostile_scalars),
)
def test_hostile_assignments_never_5xx(
    api: httpx.Client, admin: dict[str, str], lane: Any, route: Any, name: Any, params: Any
) -> None:
    body = {"lane": lane, "route": route, "controller": {"name": name, "params": params}}
    answer = api.put(
        "/api/v1/vehicles/SF-001/assignment",
        content=raw_json(body),
        headers={**admin, "content-type": "application/json"},
    )
    # 409: a valid assignment this car cannot take (a lane beyond its corridor's 4)
    assert answer.status_code in (200, 409, 422), (answer.status_code, answer.text)
