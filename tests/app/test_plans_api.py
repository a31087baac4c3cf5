"""The Speed Planner end to end on the real database and server: INRIX minutes showing a
standing slowdown and one car's pings in its lane become a published plan that vehicles read
with ETag / 304; without a valid plan the answer is 503 + Retry-After."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
import numpy as np
import pytest
from sqlalchemy import Engine, text

from app.core.config import SettingsError, load_settings
from app.core.db import make_sync_engine
from app.plans.jobs import run_planner
from contract.units import MPS_PER_MPH
from tests.planner.facts import INRIX_CODES, inrix_snapshot, standing_slowdown
from tests.support.databases import database_from_template
from tests.support.fleet import drive, post_pings
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue

LATEST = "/api/v1/plans/latest"
SPEED_LIMIT = 70 * MPS_PER_MPH
MIN_TARGET = 20 * MPS_PER_MPH


@dataclass
class Served:
    """The live server, its tokens and the plans published before the test."""

    client: httpx.Client
    tokens: dict[str, str]
    plan_ids: list[int]

    def get(self, path: str, role: str | None = "viewer", **params: Any) -> httpx.Response:
        headers = bearer(self.tokens[role]) if role else {}
        return self.client.get(path, params=params, headers=headers)


def tokens_for(engine: Engine) -> dict[str, str]:
    return {
        "viewer": issue(engine, "viewer"),
        "feed": issue(engine, "feed"),
        "vehicle": issue(engine, "vehicle", "SF-002"),
        "other_vehicle": issue(engine, "vehicle", "SF-001"),
    }


# The window the slowdowns' figures in these tests were worked out for (the recommended
# planner's is `planner.recommended.RECOMMENDED_PLANNER_PARAMS`).
HAND_WORKED_WINDOW = {"window_m": 1500.0}


@pytest.fixture
def served(seeded_database_url: str, seeded_engine: Engine) -> Iterator[Served]:
    """Four planner cycles a minute apart over a standing slowdown at 8.25-9.7 km."""
    now = datetime.now(UTC).replace(microsecond=0)
    for minute in range(12, 2, -1):
        inrix_snapshot(seeded_engine, now - timedelta(minutes=minute), standing_slowdown())
    # The full pipeline with its buffer, which these tests are about (not the default planner),
    # over the 1,500 m window the positions below were worked out for.
    settings = load_settings(
        database_url=seeded_database_url,
        planner_algorithm="kernel_smooth_buffer",
        planner_params=HAND_WORKED_WINDOW,
    )
    with (
        live_server(seeded_database_url, planner_enabled=False) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        tokens = tokens_for(seeded_engine)
        # SF-002 (lane 2) crawls at 5 m/s through the slowdown in the last minute.
        post_pings(
            client, tokens["vehicle"], drive("SF-002", now - timedelta(seconds=59), 8400, 5.0, 60)
        )
        plan_ids = []
        for minutes_ago in (3, 2, 1, 0):
            (outcome,) = run_planner(
                seeded_engine, settings, now=now - timedelta(minutes=minutes_ago)
            )
            assert outcome.status == "published", outcome.reason
            plan_ids.append(outcome.plan_id or 0)
        yield Served(client, tokens, plan_ids)


def target_at(lane: dict[str, Any], x_m: float) -> float:
    index = int(np.searchsorted(lane["x_m"], x_m, side="right")) - 1
    return float(lane["target_speed_mps"][index])


def test_the_plan_slows_ahead_of_the_bottleneck_and_is_faster_elsewhere(served: Served) -> None:
    response = served.get(LATEST, corridor="I-24-WB")
    assert response.status_code == 200, response.text
    plan = response.json()
    assert plan["plan_id"] == served.plan_ids[-1]
    assert plan["algorithm"] == "kernel_smooth_buffer"
    assert plan["inputs"]["vehicles"] == 1
    assert plan["inputs"]["pings"] == 60
    assert [lane["lane"] for lane in plan["lanes"]] == [1, 2, 3, 4]
    lane2 = plan["lanes"][1]
    assert len(lane2["x_m"]) == len(lane2["target_speed_mps"]) == 158
    # Free flow far upstream and downstream, slower approaching the slowdown, slowest in it.
    far_upstream = target_at(lane2, 2000)
    approaching = target_at(lane2, 7500)
    in_queue = target_at(lane2, 8500)
    downstream = target_at(lane2, 12500)
    assert far_upstream == pytest.approx(29.0, abs=0.01)
    assert downstream == pytest.approx(29.0, abs=0.01)
    assert in_queue < approaching < far_upstream
    assert in_queue < 0.5 * far_upstream  # its forward window is mostly queue
    # The slowdown stood through four cycles: a buffer ends where the queue begins.
    (buffer,) = lane2["buffers"]
    assert buffer["end_x_m"] <= 8251.03 + 1e-6
    assert buffer["start_x_m"] < 7500 < buffer["end_x_m"]
    assert buffer["target_speed_mps"] >= 0.8 * 7.0  # never far below the smoothed speed
    for lane in plan["lanes"]:
        assert MIN_TARGET - 1e-3 <= min(lane["target_speed_mps"])
        assert max(lane["target_speed_mps"]) <= SPEED_LIMIT + 1e-3


def test_the_car_in_lane_2_makes_its_lane_slower_than_the_others(served: Served) -> None:
    plan = served.get(LATEST, corridor="I-24-WB").json()
    lanes = {lane["lane"]: lane for lane in plan["lanes"]}
    # Its 5 m/s observations replace INRIX's 7 m/s in lane 2 only, so lane 2 slows earlier.
    assert target_at(lanes[2], 7000) < target_at(lanes[4], 7000)


def test_an_unchanged_plan_answers_304(served: Served) -> None:
    first = served.get(LATEST, corridor="I-24-WB")
    etag = first.headers["ETag"]
    again = served.client.get(
        LATEST,
        params={"corridor": "I-24-WB"},
        headers={**bearer(served.tokens["viewer"]), "If-None-Match": etag},
    )
    assert again.status_code == 304
    assert again.headers["ETag"] == etag
    assert again.content == b""
    one_lane = served.get(LATEST, corridor="I-24-WB", lane=3)
    assert one_lane.headers["ETag"] != etag
    assert [lane["lane"] for lane in one_lane.json()["lanes"]] == [3]


def test_a_vehicle_reads_its_own_lane_and_nothing_else(served: Served) -> None:
    own = served.get("/api/v1/vehicles/SF-002/plan", role="vehicle")
    assert own.status_code == 200
    assert [lane["lane"] for lane in own.json()["lanes"]] == [2]
    etag = own.headers["ETag"]
    cached = served.client.get(
        "/api/v1/vehicles/SF-002/plan",
        headers={**bearer(served.tokens["vehicle"]), "If-None-Match": etag},
    )
    assert cached.status_code == 304
    assert served.get(LATEST, role="vehicle", corridor="I-24-WB").status_code == 200
    assert served.get("/api/v1/vehicles/SF-002/plan", role="other_vehicle").status_code == 403
    assert served.get(LATEST, role="vehicle", corridor="OTHER").status_code == 403
    assert served.get(LATEST, role="feed", corridor="I-24-WB").status_code == 403
    assert served.get(LATEST, role=None, corridor="I-24-WB").status_code == 401
    missing = served.get("/api/v1/vehicles/SF-999/plan")
    assert missing.status_code == 404
    assert missing.json() == {"detail": "unknown vehicle SF-999"}


def test_bad_queries_say_what_was_wrong(served: Served) -> None:
    unknown = served.get(LATEST, corridor="I-40-EB")
    assert unknown.status_code == 404
    assert unknown.json() == {"detail": "unknown corridor I-40-EB"}
    bad_lane = served.get(LATEST, corridor="I-24-WB", lane=5)
    assert bad_lane.status_code == 404  # no plan of a lane the corridor lacks
    assert bad_lane.json() == {"detail": "no lane 5 on I-24-WB (lanes 1-4)"}


def test_the_history_lists_every_run_with_its_provenance(served: Served) -> None:
    history = served.get("/api/v1/plans", corridor="I-24-WB")
    assert history.status_code == 200
    runs = history.json()["plans"]
    assert [run["plan_id"] for run in runs] == served.plan_ids[::-1]
    newest = runs[0]
    assert newest["status"] == "published"
    # the run records the parameters it planned with
    assert newest["params"]["window_m"] == HAND_WORKED_WINDOW["window_m"]
    assert newest["inputs"]["previous_plans"] == served.plan_ids[-2::-1]
    assert newest["inputs"]["inrix_age_s"] == 180.0
    window = served.get(
        "/api/v1/plans",
        corridor="I-24-WB",
        since=runs[2]["started_at"],
        until=runs[0]["started_at"],
    ).json()["plans"]
    assert [run["plan_id"] for run in window] == [runs[1]["plan_id"], runs[2]["plan_id"]]
    assert served.get("/api/v1/plans", status="failed").json() == {
        "plans": [],
        "truncated": False,
    }
    assert history.json()["truncated"] is False
    # a window holding more runs than asked for says so; the rest lies before the oldest
    first_two = served.get("/api/v1/plans", corridor="I-24-WB", limit=2).json()
    assert [run["plan_id"] for run in first_two["plans"]] == served.plan_ids[:-3:-1]
    assert first_two["truncated"] is True
    rest = served.get(
        "/api/v1/plans", corridor="I-24-WB", until=first_two["plans"][-1]["started_at"]
    ).json()
    assert [run["plan_id"] for run in rest["plans"]] == served.plan_ids[-3::-1]
    naive = served.get("/api/v1/plans", since="2026-01-01T00:00:00")
    assert naive.status_code == 422


def test_a_history_window_that_ends_before_it_starts_is_refused(served: Served) -> None:
    """It answered an empty list, which read as no planner run in the window meant."""
    reversed_window = served.get(
        "/api/v1/plans", since="2026-01-02T00:00:00Z", until="2026-01-01T00:00:00+00:00"
    )
    assert reversed_window.status_code == 422
    assert reversed_window.json() == {
        "detail": "until (2026-01-01T00:00:00+00:00) is before since (2026-01-02T00:00:00+00:00)"
    }
    empty = served.get("/api/v1/plans", since="2026-01-01T00:00:00Z", until="2026-01-01T00:00:00Z")
    assert empty.json() == {"plans": [], "truncated": False}  # [t, t): no run, nothing wrong


def test_the_history_of_an_unknown_corridor_is_a_404_naming_it(served: Served) -> None:
    """It was 200 with no runs: a misspelt corridor read as one the planner never ran for."""
    unknown = served.get("/api/v1/plans", corridor="I-40-EB")
    assert unknown.status_code == 404
    assert unknown.json() == {"detail": "unknown corridor I-40-EB"}
    assert served.get(LATEST, corridor="I-40-EB").json() == unknown.json()  # the same answer
    assert served.get("/api/v1/plans", corridor="I-24-WB").json()["plans"]


def test_without_a_valid_plan_vehicles_are_told_to_retry(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    with (
        live_server(seeded_database_url, planner_enabled=False, planner_period_s=60) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        token = issue(seeded_engine, "vehicle", "SF-002")
        response = client.get("/api/v1/vehicles/SF-002/plan", headers=bearer(token))
        assert response.status_code == 503
        assert response.headers["Retry-After"] == "60"
        assert "no valid plan for I-24-WB" in response.json()["detail"]
        # the code a car reads to hand back (a database outage has another one)
        assert response.json()["code"] == "no_valid_plan"
        # An expired plan is no plan either.
        with seeded_engine.begin() as connection:
            connection.execute(
                text(
                    "INSERT INTO plan_run (corridor_id, status, algorithm, started_at, "
                    "published_at, valid_until) VALUES ('I-24-WB', 'published', 'kernel_smooth', "
                    "now() - interval '10 minutes', now() - interval '10 minutes', "
                    "now() - interval '7 minutes')"
                )
            )
        assert client.get("/api/v1/vehicles/SF-002/plan", headers=bearer(token)).status_code == 503


def test_two_databases_served_from_one_process_never_mix_their_plans(
    pg_server: str, seeded_template: str
) -> None:
    """Plan ids are unique only within a database: each app keeps its own rendered plans (a
    process-wide cache once served one database's plan 1 for another's)."""
    served: list[tuple[int, float]] = []
    for speeds in ([25.0] * len(INRIX_CODES), standing_slowdown()):
        with database_from_template(pg_server, seeded_template) as url:
            engine = make_sync_engine(url)
            now = datetime.now(UTC).replace(microsecond=0)
            for minute in range(8, 2, -1):
                inrix_snapshot(engine, now - timedelta(minutes=minute), speeds)
            settings = load_settings(database_url=url, planner_params=HAND_WORKED_WINDOW)
            (outcome,) = run_planner(engine, settings, now=now)
            viewer = bearer(issue(engine, "viewer"))
            engine.dispose()
            with live_server(url, planner_enabled=False) as base:
                body = httpx.get(
                    f"{base}{LATEST}",
                    params={"corridor": "I-24-WB", "lane": 1},
                    headers=viewer,
                    timeout=30,
                ).json()
            assert body["plan_id"] == outcome.plan_id
            served.append((body["plan_id"], min(body["lanes"][0]["target_speed_mps"])))
    (free_id, free_min), (slow_id, slow_min) = served
    assert free_id == slow_id  # the same id in both databases ...
    assert free_min > 20.0  # ... free flow in the first
    assert slow_min < 15.0  # ... and the slowdown in the second, not the first's document


def test_at_a_120_s_schedule_a_standing_slowdown_still_gets_its_buffer(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    # The planner's look-back spans its last cycles: at 120 s between cycles, four cycles of a
    # standing slowdown reach back 6 minutes (with a fixed 60 s look-back, never "standing").
    now = datetime.now(UTC).replace(microsecond=0)
    for minute in range(14, 0, -1):
        inrix_snapshot(seeded_engine, now - timedelta(minutes=minute), standing_slowdown())
    settings = load_settings(
        database_url=seeded_database_url,
        planner_period_s=120,
        planner_algorithm="kernel_smooth_buffer",
    )
    outcomes = [
        run_planner(seeded_engine, settings, now=now - timedelta(seconds=120 * cycles_ago))[0]
        for cycles_ago in (3, 2, 1, 0)
    ]
    assert [outcome.status for outcome in outcomes] == ["published"] * 4
    with seeded_engine.connect() as connection:
        buffered_lanes = connection.execute(
            text(
                "SELECT count(DISTINCT lane) FROM fact_speed_planner "
                "WHERE plan_id = :plan_id AND is_buffer"
            ),
            {"plan_id": outcomes[-1].plan_id},
        ).scalar_one()
    assert buffered_lanes == 4


def test_a_planner_look_back_other_than_its_schedule_is_refused() -> None:
    with pytest.raises(SettingsError, match="cycle_period_s 60 differs from"):
        load_settings(planner_period_s=120, planner_params={"cycle_period_s": 60})


def test_a_car_asks_for_the_lane_of_the_config_it_runs(served: Served) -> None:
    # SF-002 is assigned lane 2; a car still running an older config asks for its own lane
    path = "/api/v1/vehicles/SF-002/plan"
    own = served.get(path, role="vehicle")
    asked = served.get(path, role="vehicle", lane=3)
    assert [lane["lane"] for lane in own.json()["lanes"]] == [2]
    assert [lane["lane"] for lane in asked.json()["lanes"]] == [3]
    assert asked.headers["ETag"] != own.headers["ETag"]
    assert served.get(path, role="vehicle", lane=9).status_code == 404


def test_paging_the_history_by_until_skips_no_run_started_at_the_cut(
    served: Served, seeded_engine: Engine
) -> None:
    """Runs of one cycle share a start instant; the next page is asked with `until` = the
    oldest run's start, and the window ends before it: a run sharing the instant of the first
    one cut off was never returned. Such runs are left to the next page whole."""
    instant = datetime(2026, 1, 1, 12, 0, tzinfo=UTC)
    with seeded_engine.begin() as connection:
        for _ in range(3):
            connection.execute(
                text(
                    "INSERT INTO plan_run (corridor_id, status, algorithm, started_at) "
                    "VALUES ('I-24-WB', 'skipped', 'kernel_smooth', :at)"
                ),
                {"at": instant},
            )
        connection.execute(
            text(
                "INSERT INTO plan_run (corridor_id, status, algorithm, started_at) "
                "VALUES ('I-24-WB', 'skipped', 'kernel_smooth', :at)"
            ),
            {"at": instant + timedelta(minutes=1)},
        )
    window = {"since": "2026-01-01T00:00:00Z", "until": "2026-01-02T00:00:00Z"}
    seen: list[int] = []
    until = window["until"]
    for _ in range(4):
        page = served.get(
            "/api/v1/plans", corridor="I-24-WB", since=window["since"], until=until, limit=3
        ).json()
        seen += [run["plan_id"] for run in page["plans"]]
        if not page["truncated"]:
            break
        until = page["plans"][-1]["started_at"]
    everything = served.get("/api/v1/plans", corridor="I-24-WB", **window).json()["plans"]
    assert sorted(seen) == sorted(run["plan_id"] for run in everything)
    assert len(everything) == 4


def test_every_answer_to_a_vehicles_plan_poll_names_its_config_version_now(
    served: Served, seeded_engine: Engine
) -> None:
    """The car's prompt path to a new config (docs/interfaces.md): a plan, a 304, a "no
    valid plan" and a lane the corridor does not have each carry `X-Config-Version`. An
    operator's SQL that changes what the config says (pulling the car: `is_active`) bumps the
    version too, once; an API change, which sets its own, is not counted twice."""
    path = "/api/v1/vehicles/SF-002/plan"
    plan = served.get(path, role="vehicle")
    assert plan.status_code == 200
    assert plan.headers["X-Config-Version"] == "1"
    with seeded_engine.begin() as connection:
        connection.execute(
            text("UPDATE dim_vehicle SET is_active = false WHERE vehicle_id = 'SF-002'")
        )
    unchanged = served.client.get(
        path, headers={**bearer(served.tokens["vehicle"]), "If-None-Match": plan.headers["ETag"]}
    )
    assert unchanged.status_code == 304
    assert unchanged.headers["X-Config-Version"] == "2"
    operator = issue(seeded_engine, "operator")
    changed = served.client.put(
        "/api/v1/vehicles/SF-002/maintenance",
        json={"in_maintenance": True, "config_version": 2},
        headers=bearer(operator),
    )
    assert changed.status_code == 200, changed.text
    assert served.get(path, role="vehicle").headers["X-Config-Version"] == "3"
    with seeded_engine.begin() as connection:
        # an update that changes nothing the config says is no new version
        connection.execute(
            text("UPDATE dim_vehicle SET maintenance_note = 'tyres' WHERE vehicle_id = 'SF-002'")
        )
        connection.execute(text("UPDATE plan_run SET valid_until = now()"))
    none = served.get(path, role="vehicle")
    assert none.status_code == 503
    assert none.json()["code"] == "no_valid_plan"
    assert none.headers["X-Config-Version"] == "3"
    # a car moved to a corridor without the lane it polls is told its new version too
    no_lane = served.get(path, role="vehicle", lane=9)
    assert no_lane.status_code == 404, no_lane.text
    assert no_lane.headers["X-Config-Version"] == "3"
