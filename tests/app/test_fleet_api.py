"""GET /api/v1/fleet and PUT .../assignment, .../maintenance on the real server."""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from typing import Any

import httpx
import pytest
from sqlalchemy import Engine, text

from app.fleet.schemas import WHITE_SPACE
from tests.dashboards.support import add_users, logged_in
from tests.support.fleet import drive, healthy_status, post_pings, post_status
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue


class Api:
    """A client on the live server and one token per role."""

    def __init__(self, client: httpx.Client, engine: Engine) -> None:
        self.client = client
        self.tokens = {
            role: issue(engine, role)  # type: ignore[arg-type]
            for role in ("viewer", "operator", "admin", "feed")
        }
        self.tokens["vehicle"] = issue(engine, "vehicle", "SF-001")

    def get(self, path: str, role: str = "viewer", **params: Any) -> httpx.Response:
        return self.client.get(path, params=params, headers=bearer(self.tokens[role]))

    def put(self, path: str, body: object, role: str = "operator") -> httpx.Response:
        return self.client.put(path, json=body, headers=bearer(self.tokens[role]))


@pytest.fixture
def api(seeded_database_url: str, seeded_engine: Engine) -> Iterator[Api]:
    with live_server(seeded_database_url) as base, httpx.Client(base_url=base, timeout=30) as c:
        yield Api(c, seeded_engine)


def vehicle(fleet: dict[str, Any], vehicle_id: str) -> dict[str, Any]:
    (found,) = [v for v in fleet["vehicles"] if v["vehicle_id"] == vehicle_id]
    return found


def checks(entry: dict[str, Any]) -> dict[str, str]:
    return {check["name"]: check["level"] for check in entry["checks"]}


def report_healthy(api: Api, vehicle_id: str, *, status_age_s: float = 2.0) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    post_pings(
        api.client,
        api.tokens["admin"],
        drive(vehicle_id, now - timedelta(seconds=3), 2000.0, 25.0, 3, controller_engaged=True),
    )
    post_status(
        api.client,
        api.tokens["admin"],
        vehicle_id,
        **healthy_status(now - timedelta(seconds=status_age_s)),
    )


def test_the_fleet_needs_an_ops_token(api: Api) -> None:
    assert api.client.get("/api/v1/fleet").status_code == 401
    assert api.get("/api/v1/fleet", role="vehicle").status_code == 403
    assert api.get("/api/v1/fleet", role="feed").status_code == 403


def test_a_fleet_never_heard_from_is_listed_and_not_cleared(api: Api) -> None:
    response = api.get("/api/v1/fleet")

    assert response.status_code == 200
    fleet = response.json()
    assert fleet["counts"]["vehicles"] == 100
    assert fleet["counts"]["cleared"] == 0
    assert fleet["counts"]["not_cleared"] == 100
    first = vehicle(fleet, "SF-001")
    assert first["last_ping"] is None
    assert first["last_status"] is None
    assert checks(first)["status"] == "red"
    assert first["problems"] == ["never pinged", "never reported its status"]


def test_a_reporting_car_is_cleared_and_turns_red_when_its_status_goes_stale(api: Api) -> None:
    report_healthy(api, "SF-001")

    fresh = vehicle(api.get("/api/v1/fleet").json(), "SF-001")

    assert fresh["verdict"] == "cleared"
    assert set(checks(fresh).values()) == {"green"}
    assert fresh["last_ping"]["controller_engaged"] is True
    assert fresh["last_ping"]["postmile"] == pytest.approx((2000.0 + 50.0) / 1609.344, abs=1e-3)
    assert fresh["last_status"]["gps_satellites"] == 11
    counts = api.get("/api/v1/fleet").json()["counts"]
    assert (counts["cleared"], counts["reporting"], counts["engaged"]) == (1, 1, 1)

    # The car falls silent: its newest report is now 90 s old (red from 60 s).
    report_healthy(api, "SF-002", status_age_s=90.0)
    stale = vehicle(api.get("/api/v1/fleet").json(), "SF-002")
    assert checks(stale)["status"] == "red"
    assert stale["verdict"] == "not cleared"


def test_a_car_whose_clock_runs_ahead_shows_no_negative_age(api: Api) -> None:
    """Its ping and status are stamped 100 s ahead (the server takes up to 300 s): the answer
    showed ages of about -100 s while its checks read them as about 0 s (audit). Both read
    the time since the server received them now."""
    ahead = datetime.now(UTC).replace(microsecond=0) + timedelta(seconds=100)
    post_pings(api.client, api.tokens["admin"], drive("SF-001", ahead, 2000.0, 25.0, 1))
    post_status(api.client, api.tokens["admin"], "SF-001", **healthy_status(ahead))

    entry = vehicle(api.get("/api/v1/fleet").json(), "SF-001")

    assert 0.0 <= entry["last_ping"]["age_s"] < 30.0
    assert 0.0 <= entry["last_status"]["age_s"] < 30.0
    assert checks(entry)["ping"] == "green"


def test_fleet_filters_by_route_make_and_problem(api: Api) -> None:
    report_healthy(api, "SF-001")
    everyone = api.get("/api/v1/fleet").json()["vehicles"]
    route_a = [v for v in everyone if v["route"] == "A"]
    toyotas = [v for v in everyone if v["make"] == "Toyota"]

    assert len(api.get("/api/v1/fleet", route="A").json()["vehicles"]) == len(route_a)
    assert len(api.get("/api/v1/fleet", make="Toyota").json()["vehicles"]) == len(toyotas)
    not_cleared = api.get("/api/v1/fleet", problem="not-cleared").json()
    assert not_cleared["counts"]["vehicles"] == 99
    assert "SF-001" not in {v["vehicle_id"] for v in not_cleared["vehicles"]}
    # a car in maintenance is counted under maintenance, and listed there only: the filters
    # behind the counts list as many cars as the counts say (before, it was among both)
    assert api.put("/api/v1/vehicles/SF-003/maintenance", {"in_maintenance": True}).is_success
    fleet = api.get("/api/v1/fleet").json()
    listed = api.get("/api/v1/fleet", problem="not-cleared").json()["vehicles"]
    assert len(listed) == fleet["counts"]["not_cleared"] == 98
    assert "SF-003" not in {v["vehicle_id"] for v in listed}
    # the dashboard's "not cleared because of" counts: red checks of cars not cleared
    red_status = [v for v in listed if checks(v)["status"] == "red"]
    assert len(api.get("/api/v1/fleet", problem="status-red").json()["vehicles"]) == len(red_status)
    bad = api.get("/api/v1/fleet", problem="everything")
    assert bad.status_code == 422
    assert "problem must be one of" in bad.json()["detail"]


def test_an_empty_roster_is_an_empty_fleet(database_url: str, engine: Engine) -> None:
    with live_server(database_url) as base, httpx.Client(base_url=base) as client:
        token = issue(engine, "viewer")
        fleet = client.get("/api/v1/fleet", headers=bearer(token)).json()
    assert fleet["vehicles"] == []
    assert fleet["counts"]["vehicles"] == 0


ASSIGNMENT = {"lane": 3, "route": "B", "controller": {"name": "simple", "params": {"k": 0.4}}}


def test_an_operator_changes_an_assignment_and_the_car_gets_it_in_its_config(api: Api) -> None:
    response = api.put("/api/v1/vehicles/SF-001/assignment", ASSIGNMENT)

    assert response.status_code == 200, response.text
    answer = response.json()
    assert (answer["lane"], answer["route"], answer["controller"]) == (
        3,
        "B",
        {"name": "simple", "params": {"k": 0.4}},
    )
    config = api.client.get(
        "/api/v1/vehicles/SF-001/config", headers=bearer(api.tokens["vehicle"])
    ).json()
    assert config["assigned_lane"] == 3
    assert config["route"] == "B"
    assert config["controller"]["name"] == "simple"
    assert config["config_version"] == 2  # one change since the seed
    listed = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert listed["assigned_lane"] == 3


def test_a_change_made_against_an_older_config_version_is_refused(api: Api) -> None:
    # two operators read the fleet at v1; the first saves, the second's change would undo it
    read = vehicle(api.get("/api/v1/fleet").json(), "SF-001")["config_version"]
    first = api.put("/api/v1/vehicles/SF-001/assignment", {**ASSIGNMENT, "config_version": read})
    assert first.status_code == 200, first.text
    assert first.json()["config_version"] == read + 1

    second = api.put(
        "/api/v1/vehicles/SF-001/assignment",
        {**ASSIGNMENT, "route": "C", "config_version": read},
    )
    assert second.status_code == 409
    (error,) = second.json()["detail"]
    assert error["loc"] == ["body", "config_version"]
    assert f"changed since its config v{read} was read (now v{read + 1})" in error["msg"]
    listed = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert (listed["route"], listed["config_version"]) == ("B", read + 1)  # the first stands
    # a body that is wrong in itself is a 422 naming what is wrong, stale version or not
    bad = api.put(
        "/api/v1/vehicles/SF-001/assignment",
        {
            **ASSIGNMENT,
            "controller": {"name": "simple", "params": {"k": -1}},
            "config_version": read,
        },
    )
    assert bad.status_code == 422
    assert bad.json()["detail"][0]["loc"] == ["body", "controller", "params", "k"]

    # without a version the change applies, as before
    third = api.put("/api/v1/vehicles/SF-001/assignment", {**ASSIGNMENT, "route": "C"})
    assert (third.status_code, third.json()["config_version"]) == (200, read + 2)


def test_maintenance_made_against_an_older_config_version_is_refused(api: Api) -> None:
    """The maintenance switch had no version: an operator's stale page put back in service a car
    another had taken out, and erased their note."""
    read = vehicle(api.get("/api/v1/fleet").json(), "SF-002")["config_version"]
    out = api.put(
        "/api/v1/vehicles/SF-002/maintenance",
        {"in_maintenance": True, "note": "brake fault", "config_version": read},
    )
    assert (out.status_code, out.json()["config_version"]) == (200, read + 1)
    stale = api.put(
        "/api/v1/vehicles/SF-002/maintenance", {"in_maintenance": False, "config_version": read}
    )
    assert stale.status_code == 409
    (error,) = stale.json()["detail"]
    assert error["loc"] == ["body", "config_version"]
    assert "check its maintenance and save again" in error["msg"]
    listed = vehicle(api.get("/api/v1/fleet").json(), "SF-002")
    assert (listed["verdict"], listed["maintenance_note"]) == ("maintenance", "brake fault")


def test_a_viewer_may_not_change_an_assignment(api: Api) -> None:
    response = api.put("/api/v1/vehicles/SF-001/assignment", ASSIGNMENT, role="viewer")
    assert response.status_code == 403
    assert "viewer" in response.json()["detail"]
    assert vehicle(api.get("/api/v1/fleet").json(), "SF-001")["assigned_lane"] == 1


@pytest.mark.parametrize(
    ("body", "status", "field", "reason"),
    [
        # valid assignments this car cannot take: a conflict with the vehicle, not a bad body
        ({**ASSIGNMENT, "lane": 5}, 409, ["lane"], "I-24-WB has lanes 1 to 4, not 5"),
        (
            {**ASSIGNMENT, "controller": {"name": "microaccel"}},
            409,
            ["controller", "name"],
            "'microaccel' cannot drive actuation 'acc'",
        ),
        (
            {**ASSIGNMENT, "controller": {"name": "pid"}},
            422,
            ["controller", "name"],
            "'pid' is not",
        ),
        # what the agent's schema refuses is refused before it is saved
        (
            {**ASSIGNMENT, "controller": {"name": "simple", "params": {"bogus": 1}}},
            422,
            ["controller", "params", "bogus"],
            "Extra inputs are not permitted",
        ),
        (
            {**ASSIGNMENT, "controller": {"name": "simple", "params": {"k": -0.5}}},
            422,
            ["controller", "params", "k"],
            "greater than 0",
        ),
        (
            {**ASSIGNMENT, "controller": {"name": "simple", "params": {"k": "fast"}}},
            422,
            ["controller", "params", "k"],
            "valid number",
        ),
        (
            {**ASSIGNMENT, "controller": {"name": "simple", "params": {"k": "0.4"}}},
            422,
            ["controller", "params", "k"],
            "valid number",
        ),
        # said in words, where the pattern's error quoted three hundred characters of it
        (
            {**ASSIGNMENT, "route": " \t"},
            422,
            ["route"],
            "a route needs a character that is not white space",
        ),
        # integers take JSON numbers only: true moved the car to lane 1, "2" to lane 2
        ({**ASSIGNMENT, "lane": True}, 422, ["lane"], "must be a JSON number"),
        ({**ASSIGNMENT, "lane": "2"}, 422, ["lane"], "must be a JSON number"),
        ({**ASSIGNMENT, "config_version": True}, 422, ["config_version"], "JSON number"),
    ],
)
def test_an_assignment_the_car_cannot_take_is_refused_with_the_field(
    api: Api, body: dict[str, Any], status: int, field: list[str], reason: str
) -> None:
    def config() -> Any:
        path = "/api/v1/vehicles/SF-001/config"
        return api.client.get(path, headers=bearer(api.tokens["vehicle"])).json()

    before = config()
    response = api.put("/api/v1/vehicles/SF-001/assignment", body)
    assert response.status_code == status
    (error,) = response.json()["detail"]
    assert error["loc"] == ["body", *field]
    assert reason in error["msg"]
    # nothing was saved: the car's config is what it was
    assert config() == before


def test_the_documented_white_space_is_what_the_service_strips() -> None:
    white = re.compile(f"[{WHITE_SPACE}]")
    every = (chr(code) for code in range(sys.maxunicode + 1))
    assert [c for c in every if bool(white.fullmatch(c)) != c.isspace()] == []


def test_assignment_of_an_unknown_vehicle_is_404(api: Api) -> None:
    response = api.put("/api/v1/vehicles/SF-999/assignment", ASSIGNMENT)
    assert response.status_code == 404
    assert response.json()["detail"] == "unknown vehicle SF-999"


def test_an_incomplete_assignment_is_422(api: Api) -> None:
    response = api.put("/api/v1/vehicles/SF-001/assignment", {"lane": 2})
    assert response.status_code == 422


def test_a_maintenance_note_too_long_is_counted_in_characters(api: Api) -> None:
    answer = api.put(
        "/api/v1/vehicles/SF-001/maintenance", {"in_maintenance": True, "note": "x" * 501}
    )
    assert answer.status_code == 422
    assert answer.json()["detail"][0]["msg"] == "String should have at most 500 characters"
    version = api.put(
        "/api/v1/vehicles/SF-001/maintenance", {"in_maintenance": True, "config_version": True}
    )
    assert version.status_code == 422


@pytest.mark.parametrize("flag", [0, 1, "true", None])
def test_maintenance_takes_only_a_json_boolean(api: Api, flag: object) -> None:
    # a 0 read as "back in service" would clear a car its operator meant to hold
    answer = api.put("/api/v1/vehicles/SF-001/maintenance", {"in_maintenance": flag})
    assert answer.status_code == 422
    assert "in_maintenance" in str(answer.json()["detail"])


def test_a_car_in_maintenance_is_not_cleared_until_it_is_back(api: Api) -> None:
    report_healthy(api, "SF-001")
    taken = api.put(
        "/api/v1/vehicles/SF-001/maintenance", {"in_maintenance": True, "note": "CAN harness loose"}
    )
    assert taken.status_code == 200
    listed = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert (listed["verdict"], listed["maintenance_note"]) == ("maintenance", "CAN harness loose")
    assert api.get("/api/v1/fleet", problem="maintenance").json()["counts"]["maintenance"] == 1

    api.put("/api/v1/vehicles/SF-001/maintenance", {"in_maintenance": False})
    assert vehicle(api.get("/api/v1/fleet").json(), "SF-001")["verdict"] == "cleared"


def report_can_rates(api: Api, vehicle_id: str, rates: list[float], now: datetime) -> None:
    """Status reports every 10 s up to 2 s ago with these CAN rates (oldest first)."""
    post_pings(
        api.client, api.tokens["admin"], drive(vehicle_id, now - timedelta(seconds=3), 0, 25, 3)
    )
    for back, rate in enumerate(reversed(rates)):
        ts = now - timedelta(seconds=2 + 10 * back)
        post_status(
            api.client, api.tokens["admin"], vehicle_id, **healthy_status(ts, can_msgs_per_s=rate)
        )


def test_a_dip_in_one_report_does_not_flip_a_car_but_a_lasting_fault_does(api: Api) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    # 2023 Rogues send 80 frames/s (red at 8/s). SF-001 dips once; SF-002 stays low for 60 s.
    report_can_rates(api, "SF-001", [150.0] * 6 + [5.0], now)
    report_can_rates(api, "SF-002", [150.0] + [5.0] * 7, now)

    fleet = api.get("/api/v1/fleet").json()
    dipped = vehicle(fleet, "SF-001")
    assert dipped["verdict"] == "cleared"
    (can,) = [check for check in dipped["checks"] if check["name"] == "can"]
    assert (can["level"], can["value"]) == ("green", "5/s")
    assert can["pending"].startswith("red for 0 s")
    faulty = vehicle(fleet, "SF-002")
    assert faulty["verdict"] == "not cleared"
    assert faulty["problems"] == ["CAN 5/s ≤ 8/s for Rogue"]
    verdicts = [v["verdict"] for v in fleet["vehicles"]]
    assert verdicts == sorted(verdicts, key=lambda v: v != "not cleared")


def test_a_server_behind_its_fleet_ages_no_car_but_a_silent_car_among_reporting_ones_ages(
    api: Api,
) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    # Everything the server has stored is 90 s old (it fell behind): nobody is red for it.
    for vehicle_id in ("SF-001", "SF-002"):
        post_pings(
            api.client,
            api.tokens["admin"],
            drive(vehicle_id, now - timedelta(seconds=92), 0, 25, 3),
        )
        post_status(
            api.client,
            api.tokens["admin"],
            vehicle_id,
            **healthy_status(now - timedelta(seconds=90)),
        )
    behind = api.get("/api/v1/fleet").json()
    assert [checks(vehicle(behind, v))["ping"] for v in ("SF-001", "SF-002")] == ["green"] * 2
    assert vehicle(behind, "SF-001")["verdict"] == "cleared"

    # SF-001 reports again; SF-002 stays silent among reporting cars and ages.
    report_healthy(api, "SF-001")
    caught_up = api.get("/api/v1/fleet").json()
    assert checks(vehicle(caught_up, "SF-002"))["ping"] == "red"
    assert re.fullmatch(r"no ping for (8\d|9\d) s", vehicle(caught_up, "SF-002")["problems"][0])


def test_a_car_parked_since_last_night_does_not_cancel_the_servers_lag_allowance(
    api: Api, seeded_engine: Engine
) -> None:
    """Its newest ping, stored promptly 20 h ago, was the least delay of the fleet: with the
    server 90 s behind, every driving car aged to red at 6 a.m."""
    now = datetime.now(UTC).replace(microsecond=0)
    parked = drive("SF-003", now - timedelta(hours=20), 0, 25, 3)
    post_pings(api.client, api.tokens["admin"], parked)
    with seeded_engine.begin() as connection:  # stored as promptly as it was sent, back then
        connection.execute(
            text(
                "UPDATE fact_vehicle_ping SET received_at = ts + interval '0.3 s'"
                " WHERE vehicle_id = 'SF-003'"
            )
        )
    post_pings(
        api.client, api.tokens["admin"], drive("SF-001", now - timedelta(seconds=92), 0, 25, 3)
    )
    post_status(
        api.client, api.tokens["admin"], "SF-001", **healthy_status(now - timedelta(seconds=90))
    )
    driving = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert checks(driving)["ping"] == "green"
    assert driving["verdict"] == "cleared"


def test_a_server_behind_its_fleet_replays_the_whole_hold_window(api: Api) -> None:
    """Everything stored is 65 s old. The reports replayed for hysteresis run back three hold
    periods from the car's newest one: counted back from now, the window held only the last
    two, began with whichever report came first and let a CAN that has flickered for four
    minutes clear the car."""
    now = datetime.now(UTC).replace(microsecond=0)
    post_pings(
        api.client, api.tokens["admin"], drive("SF-001", now - timedelta(seconds=67), 0, 25, 3)
    )
    for back in range(25):  # every 10 s up to 65 s ago: down on even, up on odd reports back
        rate = 5.0 if back % 2 == 0 else 150.0
        ts = now - timedelta(seconds=65 + 10 * back)
        post_status(
            api.client, api.tokens["admin"], "SF-001", **healthy_status(ts, can_msgs_per_s=rate)
        )
    flickering = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert checks(flickering)["status"] == "green"  # the server's lag ages no one
    assert checks(flickering)["can"] == "red"
    assert flickering["verdict"] == "not cleared"


def reported_promptly_until(
    api: Api, engine: Engine, vehicle_id: str, *, seconds_ago: int
) -> datetime:
    """The car's pings up to 2 s before its status `seconds_ago`, each stored 0.5 s after it
    was sent (a prompt car, fallen silent since); now, to the second."""
    now = datetime.now(UTC).replace(microsecond=0)
    start = now - timedelta(seconds=seconds_ago + 2)
    post_pings(api.client, api.tokens["admin"], drive(vehicle_id, start, 0, 25, 3))
    sent = now - timedelta(seconds=seconds_ago)
    post_status(api.client, api.tokens["admin"], vehicle_id, **healthy_status(sent))
    with engine.begin() as connection:
        for table in ("fact_vehicle_ping", "fact_vehicle_status"):
            connection.execute(
                text(
                    f"UPDATE {table} SET received_at = ts + interval '0.5 s'"
                    " WHERE vehicle_id = :vehicle"
                ),
                {"vehicle": vehicle_id},
            )
    return now


def test_a_car_reporting_alone_ages_once_it_falls_silent(api: Api, seeded_engine: Engine) -> None:
    """6 a.m., one car on: it reported promptly until 100 s ago, then fell silent. Measured
    against the newest ping stored (its own), it read "0 s" and cleared for 2 minutes."""
    reported_promptly_until(api, seeded_engine, "SF-001", seconds_ago=100)
    silent = vehicle(api.get("/api/v1/fleet").json(), "SF-001")
    assert checks(silent)["ping"] == "red"
    assert re.fullmatch(r"no ping for (9\d|10\d) s", silent["problems"][0])
    assert silent["verdict"] == "not cleared"


def test_one_cars_late_pings_make_no_other_silent_car_look_fresh(
    api: Api, seeded_engine: Engine
) -> None:
    """6 a.m., two cars on. SF-002 reported promptly until 151 s ago, then fell silent; SF-001's
    one ping comes in stamped 110 s before it arrived (a clock behind, or a spool's backlog).
    The server's lag was that one delay, and every age was measured against now less it: the
    silent car read "41 s", amber, and cleared, beside a status `age_s` of 151."""
    now = reported_promptly_until(api, seeded_engine, "SF-002", seconds_ago=151)
    post_pings(
        api.client, api.tokens["admin"], drive("SF-001", now - timedelta(seconds=110), 0, 25, 1)
    )
    silent = vehicle(api.get("/api/v1/fleet").json(), "SF-002")
    assert checks(silent)["ping"] == "red"
    assert checks(silent)["status"] == "red"
    assert silent["verdict"] == "not cleared"
    assert re.fullmatch(r"no ping for 15\d s", silent["problems"][0])
    # the answer's ages are the ages graded
    assert 150 <= silent["last_status"]["age_s"] <= 160
    assert 150 <= silent["last_ping"]["age_s"] <= 160


def test_a_car_moved_to_another_corridor_is_where_its_last_ping_put_it(
    api: Api, seeded_engine: Engine
) -> None:
    """SF-050 parked 3,000 m along I-24-WB, then the roster moved it to a second corridor: its
    postmile added the new corridor's start to a position matched on the old one (a road it
    had never been on), and the map drew it there and dropped it from the road it was on."""
    now = datetime.now(UTC).replace(microsecond=0)
    post_pings(
        api.client, api.tokens["admin"], drive("SF-050", now - timedelta(seconds=3), 3000.0, 0.0, 2)
    )
    with seeded_engine.begin() as connection:
        start = connection.execute(
            text("SELECT postmile_at_start FROM dim_corridor WHERE corridor_id = 'I-24-WB'")
        ).scalar_one()
        connection.execute(
            text(
                "INSERT INTO dim_corridor (corridor_id, name, direction, lanes, length_m,"
                " speed_limit_mps, min_target_speed_mps, postmile_at_start)"
                " VALUES ('TEST-2', 'a second road', 'EB', 3, 10000, 31.3, 8.9, 100.0)"
            )
        )
        connection.execute(
            text(
                "UPDATE dim_vehicle SET corridor_id = 'TEST-2', assigned_lane = 1"
                " WHERE vehicle_id = 'SF-050'"
            )
        )
    moved = vehicle(api.get("/api/v1/fleet").json(), "SF-050")
    assert moved["last_ping"]["postmile"] == pytest.approx(start + 3000.0 / 1609.344, abs=1e-3)
    assert moved["last_ping"]["corridor_id"] == "I-24-WB"
    assert moved["corridor_id"] == "TEST-2"
    add_users(seeded_engine)
    with logged_in(str(api.client.base_url), "viewer") as viewer:
        on_its_road = viewer.get("/map", params={"corridor": "I-24-WB"}).text
        on_its_new_road = viewer.get("/map", params={"corridor": "TEST-2"}).text
    assert 'data-vehicle="SF-050"' in on_its_road
    assert 'data-vehicle="SF-050"' not in on_its_new_road
