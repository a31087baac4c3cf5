"""The dashboard's pages over HTTP: login, roles, CSRF, 404s, empty states, pages with data."""

from __future__ import annotations

import asyncio
import hashlib
import html
import re
import secrets
from collections.abc import Iterator
from datetime import UTC, datetime, time, timedelta
from zoneinfo import ZoneInfo

import httpx
import pytest
from sqlalchemy import Engine, text

from app.core.config import load_settings
from app.core.db import session_scope
from app.plans.jobs import run_planner
from app.users.service import save_user, wait_before_next_attempt
from planner.recommended import RECOMMENDED_PLANNER
from tests.dashboards.support import PASSWORDS, add_users, csrf_of, log_in, logged_in, post_form
from tests.support.fleet import drive, healthy_status, post_inrix, post_pings, post_status
from tests.support.servers import live_server
from tests.support.tokens import bearer, issue
from vehicle_agent.controllers.rl_acc import BUNDLED_POLICIES


@pytest.fixture
def site(seeded_database_url: str, seeded_engine: Engine) -> Iterator[str]:
    """The app on a seeded database with one user per role; yields its base URL."""
    add_users(seeded_engine)
    with live_server(seeded_database_url, planner_enabled=False) as base:
        yield base


@pytest.fixture
def empty_site(database_url: str, engine: Engine) -> Iterator[str]:
    """The app on a migrated database without corridor, roster or data."""
    add_users(engine)
    with live_server(database_url, planner_enabled=False) as base:
        yield base


def post_fleet_data(base: str, engine: Engine) -> None:
    """SF-001 drives engaged and reports healthy; INRIX arrives; the real planner publishes."""
    now = datetime.now(UTC).replace(microsecond=0)
    with httpx.Client(base_url=base, timeout=30) as client:
        admin = issue(engine, "admin")
        post_pings(
            client,
            admin,
            drive("SF-001", now - timedelta(seconds=60), 3000.0, 25.0, 60, controller_engaged=True),
        )
        post_status(client, admin, "SF-001", **healthy_status(now - timedelta(seconds=2)))
        with engine.connect() as connection:
            codes = list(
                connection.execute(
                    text("SELECT xd_code FROM dim_inrix_segment ORDER BY seq")
                ).scalars()
            )
        for minutes_ago in (3, 2):
            post_inrix(
                client,
                admin,
                now - timedelta(minutes=minutes_ago),
                {code: 25.0 if 8 <= seq <= 10 else 62.0 for seq, code in enumerate(codes)},
            )
    url = engine.url.render_as_string(hide_password=False)
    outcomes = run_planner(engine, load_settings(database_url=url))
    assert outcomes[0].status == "published", outcomes


# --- login --------------------------------------------------------------------------------------


def test_pages_send_a_visitor_to_the_login_form(site: str) -> None:
    with httpx.Client(base_url=site) as client:
        response = client.get("/vehicles/SF-001")
        assert response.status_code == 303
        assert response.headers["location"] == "/login?next=%2Fvehicles%2FSF-001"
        live = client.get("/fleet/live", headers={"X-Requested-With": "fetch"})
        assert live.status_code == 401


def test_login_sets_a_protected_session_cookie_and_goes_where_the_user_was_going(
    site: str,
) -> None:
    with httpx.Client(base_url=site) as client:
        response = log_in(client, "viewer", PASSWORDS["viewer"], "/vehicles/SF-002")
        assert response.status_code == 303
        assert response.headers["location"] == "/vehicles/SF-002"
        cookie = response.headers["set-cookie"]
        assert "sf_session=" in cookie
        assert "HttpOnly" in cookie
        assert "SameSite=lax" in cookie
        page = client.get("/fleet")
        assert page.status_code == 200
        assert page.text.count('<tr data-vehicle="') == 100


@pytest.mark.parametrize(
    ("username", "password"),
    [("viewer", "wrong-password"), ("nobody", "x"), ("vie\x00wer", PASSWORDS["viewer"])],
    ids=["wrong-password", "no-account", "nul-in-name"],
)
def test_a_wrong_login_says_so_without_telling_which_part(
    site: str, username: str, password: str
) -> None:
    with httpx.Client(base_url=site) as client:
        response = log_in(client, username, password)
        assert response.status_code == 401
        assert "Wrong username or password." in response.text
        assert client.get("/fleet").status_code == 303


def test_repeated_failures_make_the_account_wait(site: str, seeded_engine: Engine) -> None:
    with httpx.Client(base_url=site) as client:
        for _ in range(3):
            assert log_in(client, "operator", "guess-guess").status_code == 401
        # The third failure in a row: even the right password must wait a second.
        locked = log_in(client, "operator", PASSWORDS["operator"])
        assert locked.status_code == 429
        assert "Too many failed logins for this account" in locked.text
        assert locked.headers["retry-after"] == "1"
        with seeded_engine.begin() as connection:
            failures = connection.execute(
                text("SELECT failed_logins FROM ops_user WHERE username = 'operator'")
            ).scalar_one()
            assert failures == 3
            # ... and after the wait it is let in, which resets the count.
            connection.execute(
                text(
                    "UPDATE ops_login_failure SET last_failed_at = now() - interval '2 s' "
                    "WHERE username = 'operator'"
                )
            )
        assert log_in(client, "operator", PASSWORDS["operator"]).status_code == 303
        with seeded_engine.begin() as connection:
            assert (
                connection.execute(
                    text("SELECT failed_logins FROM ops_user WHERE username = 'operator'")
                ).scalar_one()
                == 0
            )
            assert connection.execute(text("SELECT count(*) FROM ops_login_failure")).scalar() == 0


def test_a_strangers_failures_do_not_keep_the_owner_out(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """The wait was the account's: one wrong guess every five minutes from anywhere kept the
    owner out for good. It is counted per (account, client address): the stranger waits, the
    owner from another address is let in, and the owner's success leaves the stranger's count."""
    add_users(seeded_engine)
    stranger = {"X-Forwarded-For": "203.0.113.9"}
    owner = {"X-Forwarded-For": "198.51.100.7"}
    with live_server(
        seeded_database_url, planner_enabled=False, trusted_proxies="127.0.0.1"
    ) as base:
        with httpx.Client(base_url=base, headers=stranger) as client:
            for _ in range(3):
                assert log_in(client, "admin", "guess-guess").status_code == 401
            waiting = log_in(client, "admin", PASSWORDS["admin"])
            assert waiting.status_code == 429
            assert "from this address" in waiting.text
        with httpx.Client(base_url=base, headers=owner) as client:
            assert log_in(client, "admin", PASSWORDS["admin"]).status_code == 303
    with seeded_engine.begin() as connection:
        rows = connection.execute(
            text("SELECT client_address, failures FROM ops_login_failure WHERE username = 'admin'")
        ).all()
    assert [tuple(row) for row in rows] == [("203.0.113.9", 3)]


def test_a_username_that_is_no_account_waits_as_an_account_does(site: str) -> None:
    """Only real accounts slowed down: from the fourth guess a real username answered 429 and
    a made-up one 401, so three bad guesses told which usernames exist."""
    answers = {}
    with httpx.Client(base_url=site) as client:
        for username in ("viewer", f"nobody-{secrets.token_hex(4)}"):
            for _ in range(3):
                assert log_in(client, username, "guess-guess").status_code == 401
            fourth = log_in(client, username, "guess-guess")
            answers[username != "viewer"] = (
                fourth.status_code,
                fourth.headers.get("retry-after"),
                "Too many failed logins for this account" in fourth.text,
            )
    assert answers[True] == answers[False] == (429, "1", True)


def test_the_wait_doubles_with_each_failure_up_to_five_minutes() -> None:
    assert [wait_before_next_attempt(n) for n in range(7)] == [0, 0, 0, 1, 2, 4, 8]
    assert wait_before_next_attempt(40) == 300
    # days of one address failing on one account: the wait, not a 500 (2.0 ** 1100 overflowed)
    assert wait_before_next_attempt(1_100) == 300


def test_a_login_form_without_its_token_is_refused(site: str) -> None:
    with httpx.Client(base_url=site) as client:
        response = client.post(
            "/login", data={"username": "viewer", "password": PASSWORDS["viewer"]}
        )
        assert response.status_code == 403
        assert "did not come from this site" in response.text


def test_login_never_redirects_to_another_site(site: str) -> None:
    with httpx.Client(base_url=site) as client:
        response = log_in(client, "viewer", PASSWORDS["viewer"], "//evil.example/")
        assert response.headers["location"] == "/fleet"


def test_a_new_password_ends_old_sessions(site: str, seeded_engine: Engine) -> None:
    with logged_in(site, "viewer") as client:
        assert client.get("/fleet").status_code == 200
        with session_scope(seeded_engine) as session:
            save_user(session, "viewer", "viewer", "a-brand-new-password")
        assert client.get("/fleet").status_code == 303


def test_a_forged_cookie_with_any_text_is_sent_to_the_login(site: str) -> None:
    """A signature with a non-ASCII character made hmac.compare_digest raise: a 500 with a
    traceback on every page, for anyone, the error page itself included."""
    for signature in ("def", "d\xe9f"):
        cookie = f"sf_session=YWJj.{signature}".encode("latin-1")
        with httpx.Client(base_url=site, timeout=30) as client:
            response = client.get("/fleet", headers={"Cookie": cookie})
        assert response.status_code == 303, signature
        assert response.headers["location"].startswith("/login")


def test_logout_ends_the_session(site: str) -> None:
    with logged_in(site, "viewer") as client:
        response = post_form(client, "/fleet", "/logout")
        assert response.status_code == 303
        assert client.get("/fleet").status_code == 303


def test_logout_ends_a_copy_of_the_cookie_and_the_users_other_sessions(site: str) -> None:
    """Logging out only deleted the browser's cookie: a copy of it (a shared computer, a
    proxy's log) opened the dashboard for the rest of its 12 h. Every session of the user
    issued before the logout ends; a new login works."""
    with logged_in(site, "operator") as client, logged_in(site, "operator") as other_device:
        copied = client.cookies.get("sf_session")
        assert copied is not None
        assert post_form(client, "/fleet", "/logout").status_code == 303
        with httpx.Client(base_url=site, timeout=30) as thief:
            thief.cookies.set("sf_session", copied)
            assert thief.get("/fleet").status_code == 303
        assert other_device.get("/fleet").status_code == 303
    with logged_in(site, "operator") as again:
        assert again.get("/fleet").status_code == 200


# --- roles and CSRF -----------------------------------------------------------------------------


def test_a_viewer_cannot_change_an_assignment(site: str, seeded_engine: Engine) -> None:
    with logged_in(site, "viewer") as client:
        page = client.get("/vehicles/SF-001")
        assert "Save assignment" not in page.text
        assert "Your role is viewer" in page.text
        response = post_form(
            client,
            "/vehicles/SF-001",
            "/vehicles/SF-001/assignment",
            lane="3",
            route="B",
            controller="simple",
        )
        assert response.status_code == 403
        assert "only operators and admins can change vehicles" in response.text
    with seeded_engine.connect() as connection:
        lane = connection.execute(
            text("SELECT assigned_lane FROM dim_vehicle WHERE vehicle_id = 'SF-001'")
        ).scalar_one()
    assert lane == 1


def test_an_operator_changes_an_assignment_from_the_vehicle_page(site: str) -> None:
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-001",
            "/vehicles/SF-001/assignment",
            lane="3",
            route="B",
            controller="simple",
            params='{"k": 0.4}',
        )
        assert response.status_code == 303
        page = client.get(response.headers["location"])
        assert "Assignment saved." in page.text
        assert '<strong data-field="lane">3</strong>' in page.text
        assert '<strong data-field="route">B</strong>' in page.text


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"lane": "7"}, "lane: I-24-WB has lanes 1 to 4, not 7"),
        ({"params": "{gain"}, "controller.params: not valid JSON"),
        ({"controller": "microaccel"}, "controller.name: 'microaccel' cannot drive actuation"),
        ({"params": '{"bogus": 1}'}, "controller.params.bogus: Extra inputs are not permitted"),
        ({"params": '{"k": -0.5}'}, "controller.params.k: Input should be greater than 0"),
        ({"params": '{"k": "fast"}'}, "controller.params.k: Input should be a valid number"),
        # what the API's schema refuses (before, a JSON error page, or a 65-character route saved)
        ({"route": "A\x00B"}, "route: text must not contain the NUL character"),
        ({"route": "R" * 65}, "route: at most 64 characters, not 65"),
    ],
)
def test_an_assignment_the_car_cannot_take_is_shown_and_not_saved(
    site: str, fields: dict[str, str], message: str
) -> None:
    form = {"lane": "2", "route": "B", "controller": "simple", "params": "{}", **fields}
    with logged_in(site, "operator") as client:
        response = post_form(client, "/vehicles/SF-001", "/vehicles/SF-001/assignment", **form)
        assert response.status_code == 422
        assert "Not saved:" in response.text
        # beside the field it is about
        assert f'<span class="field-error" role="alert" data-field="{message.split(":")[0]}">' in (
            response.text
        )
        assert message.replace("'", "&#39;") in response.text
        # the form as the operator filled it in, every field it can show (before, only the
        # parameters: the route went back to A, the lane and controller to the stored ones)
        assert f'name="route" value="{form["route"]}"' in response.text
        for name in ("lane", "controller"):
            if f'<option value="{form[name]}" ' in response.text:  # one the form offers
                assert f'<option value="{form[name]}" selected>' in response.text
        # and nothing saved
        page = client.get("/vehicles/SF-001")
        assert '<strong data-field="route">A</strong>' in page.text


def test_two_operators_on_one_car_do_not_overwrite_each_other(site: str) -> None:
    with logged_in(site, "operator") as first, logged_in(site, "operator") as second:
        # both open SF-002's page, on the same config
        versions = [
            re.search(r'name="config_version" value="(\d+)"', c.get("/vehicles/SF-002").text)
            for c in (first, second)
        ]
        assert versions[0] is not None
        assert versions[1] is not None

        def save(client: httpx.Client, route: str, version: str) -> httpx.Response:
            return post_form(
                client,
                "/vehicles/SF-002",
                "/vehicles/SF-002/assignment",
                lane="2",
                controller="simple",
                params="{}",
                route=route,
                config_version=version,
            )

        assert save(first, "B", versions[0].group(1)).status_code == 303
        # the second saves what it filled in against the page it opened before that
        stale = save(second, "C", versions[1].group(1))
        assert stale.status_code == 422
        assert "the vehicle was changed since its config v" in stale.text
        page = second.get("/vehicles/SF-002").text
        assert '<strong data-field="route">B</strong>' in page  # the first's change stands


def test_a_stale_maintenance_form_does_not_put_a_car_back_in_service(site: str) -> None:
    """The maintenance form carried no version: an operator whose page still showed the car in
    service saved it back into service over another's "do not deploy", note and all."""
    with logged_in(site, "operator") as first, logged_in(site, "operator") as second:
        opened = re.search(
            r'name="config_version" value="(\d+)"', second.get("/vehicles/SF-004").text
        )
        assert opened is not None
        taken_out = post_form(
            first,
            "/vehicles/SF-004",
            "/vehicles/SF-004/maintenance",
            in_maintenance="on",
            note="brake fault: do not deploy",
            config_version=opened.group(1),
        )
        assert taken_out.status_code == 303
        stale = post_form(
            second,
            "/vehicles/SF-004",
            "/vehicles/SF-004/maintenance",
            note="wheel alignment checked",
            config_version=opened.group(1),
        )
        assert stale.status_code == 422
        assert "the vehicle was changed since its config v" in stale.text
        # what the second typed is still in the form to save again, not thrown away
        assert 'name="note" value="wheel alignment checked"' in stale.text
        page = second.get("/vehicles/SF-004").text
        # the first's change stands, and says who made it and when
        assert re.search(
            r"in maintenance since [^<]+ by dashboard user operator: brake fault: do not deploy",
            page,
        )
        assert "taken out for maintenance: brake fault: do not deploy" in page


def test_an_open_page_shows_an_assignment_another_operator_saved(site: str) -> None:
    """The line with the car's route and lane stood outside the refreshed part: an open page
    went on saying lane 4 while its checks said the car was not in its assigned lane."""
    with logged_in(site, "operator") as first, logged_in(site, "viewer") as watching:
        assert '<strong data-field="route">B</strong>' not in watching.get("/vehicles/SF-005").text
        saved = post_form(
            first,
            "/vehicles/SF-005",
            "/vehicles/SF-005/assignment",
            lane="1",
            controller="simple",
            params="{}",
            route="B",
        )
        assert saved.status_code == 303
        refreshed = watching.get("/vehicles/SF-005/live").text
        assert '<strong data-field="route">B</strong>' in refreshed
        assert '<strong data-field="lane">1</strong>' in refreshed
        assert re.search(
            r"dashboard user operator</td><td>v\d+</td>\s*<td>lane 1, route B", refreshed
        )


def test_a_form_sent_back_for_a_mistake_still_knows_which_config_its_operator_read(
    site: str,
) -> None:
    """The redrawn form carried the version now stored: an operator who fixed a typo saved over
    a change someone else made meanwhile, never told of it."""
    with logged_in(site, "operator") as first, logged_in(site, "operator") as second:
        opened = re.search(
            r'name="config_version" value="(\d+)"', second.get("/vehicles/SF-003").text
        )
        assert opened is not None

        def save(client: httpx.Client, route: str, version: str, params: str) -> httpx.Response:
            return post_form(
                client,
                "/vehicles/SF-003",
                "/vehicles/SF-003/assignment",
                lane="1",
                controller="simple",
                params=params,
                route=route,
                config_version=version,
            )

        assert save(first, "B", opened.group(1), "{}").status_code == 303
        typo = save(second, "C", opened.group(1), "{")
        assert typo.status_code == 422
        assert "controller.params: not valid JSON" in typo.text
        kept = re.search(r'name="config_version" value="(\d+)"', typo.text)
        assert kept is not None
        assert kept.group(1) == opened.group(1)
        fixed = save(second, "C", kept.group(1), "{}")
        assert fixed.status_code == 422
        assert "the vehicle was changed since its config v" in fixed.text
        # the conflict hands over the version now stored, to save against once checked
        now = re.search(r'name="config_version" value="(\d+)"', fixed.text)
        assert now is not None
        assert int(now.group(1)) == int(opened.group(1)) + 1
        assert save(second, "C", now.group(1), "{}").status_code == 303


# 5,000 digits: more than Python reads as an integer (a ValueError, which was a 500)
@pytest.mark.parametrize("version", ["²", "v3", "-1", "9" * 5000])
def test_a_config_version_that_is_no_number_is_refused_by_name(site: str, version: str) -> None:
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-001",
            "/vehicles/SF-001/assignment",
            lane="1",
            controller="simple",
            params="{}",
            route="Z",
            config_version=version,
        )
        assert response.status_code == 422
        assert "config_version:" in response.text
        assert "is not a config version" in response.text
        assert '<strong data-field="route">Z</strong>' not in client.get("/vehicles/SF-001").text


def test_controller_parameters_nested_deeper_than_json_reads_are_refused_by_name(
    site: str,
) -> None:
    """100,000 "[" ended the JSON parser in a RecursionError: a 500."""
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-001",
            "/vehicles/SF-001/assignment",
            lane="1",
            controller="simple",
            params="[" * 100_000,
            route="Z",
        )
        assert response.status_code == 422
        assert "controller.params: nested too deeply" in response.text


def test_a_maintenance_config_version_too_long_to_read_is_refused_by_name(site: str) -> None:
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-004",
            "/vehicles/SF-004/maintenance",
            in_maintenance="on",
            note="brake light",
            config_version="9" * 5000,
        )
        assert response.status_code == 422
        assert "is not a config version" in response.text


def test_a_maintenance_note_the_database_cannot_store_is_shown_and_not_saved(site: str) -> None:
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-004",
            "/vehicles/SF-004/maintenance",
            in_maintenance="on",
            note="UPS\x00battery",
        )
        assert response.status_code == 422
        assert "note: text must not contain the NUL character" in response.text
        fleet = client.get("/fleet", params={"problem": "maintenance"}).text
        assert "SF-004" not in fleet


def test_a_form_without_the_session_token_is_refused(site: str) -> None:
    with logged_in(site, "admin") as client:
        response = client.post(
            "/vehicles/SF-001/maintenance", data={"in_maintenance": "on", "csrf_token": "forged"}
        )
        assert response.status_code == 403
        assert "did not come from this site" in response.text


def test_an_operator_marks_a_car_in_maintenance(site: str) -> None:
    with logged_in(site, "operator") as client:
        response = post_form(
            client,
            "/vehicles/SF-004",
            "/vehicles/SF-004/maintenance",
            in_maintenance="on",
            note="replace UPS battery",
        )
        assert response.status_code == 303
        fleet = client.get("/fleet", params={"problem": "maintenance"}).text
        assert fleet.count('<tr data-vehicle="') == 1
        assert 'data-vehicle="SF-004" data-verdict="maintenance"' in fleet


# --- unknown things and empty states ------------------------------------------------------------


def test_every_asset_a_page_links_is_served_by_the_site_itself(site: str) -> None:
    """The pages named no icon, so a browser asked for /favicon.ico and got a 404; and the
    dashboard fetches nothing from the internet."""
    with logged_in(site, "viewer") as client:
        html = client.get("/fleet").text
        assets = re.findall(r'<(?:link|script)[^>]+(?:href|src)="([^"]+)"', html)
        assert "/static/favicon.svg" in assets
        for asset in assets:
            assert asset.startswith("/"), asset
            assert client.get(asset).status_code == 200, asset


def test_an_unknown_vehicle_is_a_404_page(site: str) -> None:
    with logged_in(site, "viewer") as client:
        response = client.get("/vehicles/SF-999")
        assert response.status_code == 404
        assert "There is no vehicle SF-999 in the roster" in response.text
        assert "Traceback" not in response.text


def test_an_unknown_page_is_an_html_page_with_the_menu(site: str) -> None:
    page = {"Accept": "text/html"}
    with logged_in(site, "viewer") as client:
        response = client.get("/no-such-page", headers=page)
        assert response.status_code == 404
        assert response.headers["content-type"].startswith("text/html")
        assert "<h1>Page not found</h1>" in response.text
        assert '<a href="/fleet"' in response.text
        assert "viewer" in response.text  # the logged-in menu, with the logout button
        vehicle = client.get("/vehicles/SF-999", headers=page)
        assert '<a href="/map"' in vehicle.text
    with httpx.Client(base_url=site) as visitor:
        anonymous = visitor.get("/no-such-page", headers=page)
        assert anonymous.status_code == 404
        assert '<a href="/login">Log in</a>' in anonymous.text
        api = visitor.get("/api/v1/no-such-thing", headers=page)
        assert api.status_code == 404
        assert api.json() == {"detail": "Not Found"}
        assert visitor.get("/no-such-page").json() == {"detail": "Not Found"}  # not a browser


def test_a_parameter_a_page_refuses_is_an_html_page_that_names_it(site: str) -> None:
    page = {"Accept": "text/html"}
    with logged_in(site, "viewer") as client:
        response = client.get("/timespace", params={"hours": "100", "lane": "x"}, headers=page)
        assert response.status_code == 422
        assert response.headers["content-type"].startswith("text/html")
        assert "<h1>Not a valid address</h1>" in response.text
        assert "hours: Input should be less than or equal to 24" in response.text
        assert "lane: Input should be a valid integer" in response.text
        assert '<a href="/fleet"' in response.text  # the menu, to go on from
        # a client that is not a browser keeps FastAPI's JSON answer
        api = client.get("/timespace", params={"hours": "100"})
        assert api.status_code == 422
        assert api.json()["detail"][0]["loc"] == ["query", "hours"]


def test_an_address_no_plan_or_vehicle_can_have_is_an_html_page_that_names_it(site: str) -> None:
    """A plan id beyond bigint and a NUL in a vehicle id reached the database, whose refusal
    came back as the API's JSON 422 to a browser."""
    page = {"Accept": "text/html"}
    with logged_in(site, "viewer") as client:
        for path, reason in (
            ("/plans/99999999999999999999", "plan_id: Input should be less than or equal to"),
            ("/vehicles/%00", "vehicle_id: String should match pattern"),
            ("/vehicles/%00/live", "vehicle_id: String should match pattern"),
            ("/vehicles/SF%00/history/live", "vehicle_id: String should match pattern"),
        ):
            response = client.get(path, headers=page)
            assert response.status_code == 422, path
            assert response.headers["content-type"].startswith("text/html"), path
            assert "<h1>Not a valid address</h1>" in response.text, path
            assert reason in html.unescape(response.text), path
            assert '<a href="/fleet"' in response.text, path
    with logged_in(site, "operator") as operator:
        form = operator.get("/vehicles/SF-001").text
        for action in ("assignment", "maintenance"):
            posted = operator.post(
                f"/vehicles/%00/{action}", data={"csrf_token": csrf_of(form)}, headers=page
            )
            assert posted.status_code == 422, action
            assert "<h1>Not a valid address</h1>" in posted.text, action
            assert "vehicle_id: String should match pattern" in html.unescape(posted.text)
    with logged_in(site, "viewer") as client:
        # a client that is not a browser keeps FastAPI's JSON answer, as the API's own paths do
        api = client.get("/plans/99999999999999999999")
        assert api.status_code == 422
        assert api.json()["detail"][0]["loc"] == ["path", "plan_id"]
        for api_path in ("/api/v1/vehicles/%00/plan", "/api/v1/no-such-thing/%00"):
            refused = client.get(api_path, headers=page)
            assert refused.headers["content-type"] == "application/json", api_path


def test_a_failing_page_is_a_500_page_and_the_api_keeps_its_answer(database_url: str) -> None:
    from smoothfleet.server import create_app

    app = create_app(load_settings(database_url=database_url))

    @app.get("/broken-page")
    async def broken_page() -> None:
        raise RuntimeError("a bug in a page")

    @app.get("/api/v1/broken")
    async def broken_api() -> None:
        raise RuntimeError("a bug in the API")

    async def ask(path: str) -> httpx.Response:
        transport = httpx.ASGITransport(app, raise_app_exceptions=False)
        async with httpx.AsyncClient(transport=transport, base_url="http://test") as client:
            return await client.get(path, headers={"Accept": "text/html"})

    page = asyncio.run(ask("/broken-page"))
    assert page.status_code == 500
    assert "<h1>Something went wrong</h1>" in page.text
    assert "a bug in a page" not in page.text
    api = asyncio.run(ask("/api/v1/broken"))
    assert (api.status_code, api.text) == (500, "Internal Server Error")


def test_an_unknown_plan_is_a_404_page(site: str) -> None:
    with logged_in(site, "viewer") as client:
        response = client.get("/plans/424242")
        assert response.status_code == 404
        assert "There is no plan 424242" in response.text


def test_plans_of_an_unknown_corridor_are_a_404_page(site: str) -> None:
    """They were the first corridor's plans, under a heading that alone told them apart."""
    with logged_in(site, "viewer") as client:
        for path in ("/plans", "/plans/live"):
            response = client.get(path, params={"corridor": "I-24-EB"})
            assert response.status_code == 404, path
            assert "There is no corridor I-24-EB" in response.text


def test_a_lane_or_window_the_menus_do_not_offer_is_refused_or_offered(site: str) -> None:
    """A lane beyond the corridor's drew that lane under a menu showing lane 1, and hours not
    in the menu drew under a menu showing 0.5 h: the next automatic refresh switched views."""
    with logged_in(site, "viewer") as client:
        for path in ("/timespace", "/plans"):
            response = client.get(path, params={"lane": 7})
            assert response.status_code == 422, path
            assert "I-24-WB has lanes 1 to 4, not 7" in response.text
        page = client.get("/timespace", params={"hours": 3}).text
        assert '<option value="3.0" selected>3.0 h</option>' in page


def test_the_feeds_page_says_when_its_newest_minute_of_pings_was(
    site: str, seeded_engine: Engine
) -> None:
    """It read "last minute: 1.0 pings/s" for a fleet silent for the last 50 minutes."""
    start = datetime.now(UTC).replace(second=0, microsecond=0) - timedelta(minutes=51)
    with httpx.Client(base_url=site, timeout=30) as api:
        post_pings(api, issue(seeded_engine, "admin"), drive("SF-001", start, 3000.0, 25.0, 60))
    with logged_in(site, "viewer") as client:
        feeds = client.get("/feeds/live").text
    age = re.search(r'data-field="pings-minute-age">(\d+) min<', feeds)
    assert age is not None, feeds
    assert 49 <= int(age.group(1)) <= 51
    assert "1.0 pings/s from 1 vehicle(s)" in feeds


def test_an_unknown_filter_is_explained(site: str) -> None:
    with logged_in(site, "viewer") as client:
        response = client.get("/fleet", params={"problem": "everything"})
        assert response.status_code == 400
        assert "no problem filter called 'everything'" in html.unescape(response.text)


@pytest.mark.parametrize(
    ("path", "says"),
    [
        ("/fleet", "No vehicles in the roster yet"),
        ("/plans", "No corridor yet"),
        ("/feeds", "No INRIX data yet"),
        ("/analytics", "No pings on the corridor in the last 30 days"),
        ("/map", "No corridor yet"),
        ("/timespace", "No corridor yet"),
    ],
)
def test_every_page_works_on_an_empty_database(empty_site: str, path: str, says: str) -> None:
    with logged_in(empty_site, "viewer") as client:
        response = client.get(path)
        assert response.status_code == 200
        assert says in response.text


@pytest.mark.parametrize(
    ("path", "says"),
    [
        ("/plans", "No plan published yet"),
        ("/vehicles/SF-010", "No pings from this vehicle yet"),
        ("/feeds", "No pings in the last hour"),
        ("/analytics", "No ping has followed a plan in the last 7 days"),
        ("/timespace", "No pings and no plans on I-24-WB in the last 2.0 h"),
    ],
)
def test_pages_of_a_fleet_without_data_say_what_to_do(site: str, path: str, says: str) -> None:
    with logged_in(site, "viewer") as client:
        response = client.get(path)
        assert response.status_code == 200
        assert says in response.text


def test_filters_that_match_nothing_say_so(site: str) -> None:
    with logged_in(site, "viewer") as client:
        response = client.get("/fleet", params={"route": "Z"})
        assert "No vehicle matches these filters" in response.text


# --- pages with data ----------------------------------------------------------------------------


def test_pages_show_the_data_posted_through_the_api(site: str, seeded_engine: Engine) -> None:
    post_fleet_data(site, seeded_engine)
    with logged_in(site, "viewer") as client:
        fleet = client.get("/fleet").text
        assert 'data-vehicle="SF-001" data-verdict="cleared"' in fleet
        assert '<span class="number" data-count="cleared">1</span>' in fleet

        live = client.get("/fleet/live", params={"route": "A"}).text
        assert "<html" not in live
        assert 'data-vehicle="SF-001"' in live

        vehicle = client.get("/vehicles/SF-001").text
        assert 'data-chart="vehicle-speed"' in vehicle
        assert 'data-chart="vehicle-engagement"' in vehicle
        assert "100 %" in vehicle  # every ping engaged
        assert "1.0.0" in vehicle  # the status history shows the agent version
        assert 'data-live-url="/vehicles/SF-001/live"' in vehicle
        vehicle_live = client.get("/vehicles/SF-001/live").text
        assert "<html" not in vehicle_live
        assert 'data-field="verdict">cleared</span>' in vehicle_live
        assert vehicle_live.count('class="check-card') == 12
        assert 'data-live-url="/vehicles/SF-001/history/live"' in vehicle
        history = client.get("/vehicles/SF-001/history/live").text
        assert "<html" not in history
        assert "data-generated-at=" in history
        for chart in ("vehicle-speed", "vehicle-engagement"):
            assert f'data-chart="{chart}"' in history

        plans = client.get("/plans").text
        for chart in ("plan-lane-1", "plan-lane-4", "plan-heatmap", "tse-heatmap"):
            assert f'data-chart="{chart}"' in plans
        assert 'alt="Target speed of lane 1 along the corridor"' in plans  # axes: test_charts
        assert f"<dt>algorithm</dt><dd>{RECOMMENDED_PLANNER}</dd>" in plans
        assert 'data-live-url="/plans/live?corridor=I-24-WB&amp;lane=1"' in plans
        plans_live = client.get("/plans/live", params={"corridor": "I-24-WB", "lane": 2}).text
        assert "<html" not in plans_live
        assert "data-generated-at=" in plans_live
        assert 'data-chart="plan-heatmap"' in plans_live
        assert "Target speed of lane 2, recent plans" in plans_live
        plan_id = re.search(r"<h2>Plan (\d+) ", plans)
        assert plan_id is not None
        one_plan = client.get(f"/plans/{plan_id.group(1)}").text
        assert "data-live-url" not in one_plan  # a plan run as published does not change
        assert "the latest plan</a> updates itself" in one_plan

        feeds = client.get("/feeds").text
        assert 'data-live-url="/feeds/live"' in feeds
        feeds_live = client.get("/feeds/live").text
        assert "<html" not in feeds_live
        assert 'data-chart="ping-rate"' in feeds_live
        assert 'data-field="inrix-latency"' in feeds
        assert 'data-chart="ping-rate"' in feeds

        analytics = client.get("/analytics").text
        for chart in ("engagement-share", "pings-hourly", "vehicles-hourly", "edie-speed"):
            assert f'data-chart="{chart}"' in analytics
        assert 'data-live-url="/analytics/live"' in analytics
        analytics_live = client.get("/analytics/live").text
        assert "<html" not in analytics_live
        assert "data-generated-at=" in analytics_live
        assert 'data-chart="engagement-share"' in analytics_live

        corridor_map = client.get("/map").text
        assert 'data-vehicle="SF-001" data-state="engaged"' in corridor_map
        # the 99 cars that never pinged are counted, as the fleet page counts them (the map
        # said "0 not reporting" while the fleet page said 1 of 100 reporting)
        assert '<span class="number" data-state-count="not placed">99</span>' in corridor_map
        assert "lane 1: " in corridor_map
        assert "no plan" not in corridor_map

        time_space = client.get("/timespace", params={"field": "tse"}).text
        assert 'data-chart="time-space"' in time_space
        assert '<span class="number" data-field="cars">1</span>' in time_space
        assert '<span class="number" data-field="window-share">100 %</span>' in time_space
        assert "No plan of lane 1" not in time_space
        assert client.get("/timespace", params={"field": "fuel"}).status_code == 400


def test_the_status_history_says_why_the_agent_stopped(site: str, seeded_engine: Engine) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    with httpx.Client(base_url=site, timeout=30) as client:
        admin = issue(seeded_engine, "admin")
        stopped = healthy_status(
            now - timedelta(seconds=12),
            controller_running=False,
            engage_reason="button presses not confirmed by the car",
        )
        post_status(client, admin, "SF-003", **stopped)
        post_status(client, admin, "SF-003", **healthy_status(now - timedelta(seconds=2)))
    with logged_in(site, "viewer") as client:
        history = client.get("/vehicles/SF-003/history/live").text
    # only the report where it had stopped carries a reason, beside the controller
    assert history.count('data-field="engage-reason"') == 1
    assert (
        '(stopped: <span data-field="engage-reason">button presses not confirmed by the car'
        "</span>)" in history
    )


def test_days_are_the_corridors_local_days(site: str, seeded_engine: Engine) -> None:
    # Yesterday in Nashville (UTC-6 in winter, -5 in summer) from 17:30 to 19:30: the first
    # hour is engaged, the second not. In UTC the evening spans two days; locally it is one.
    zone = ZoneInfo(load_settings().dashboard_timezone)
    yesterday = datetime.now(zone).date() - timedelta(days=1)
    evening = datetime.combine(yesterday, time(17, 30), zone).astimezone(UTC)
    assert evening.date() != (evening + timedelta(hours=2)).date()  # two UTC days
    with httpx.Client(base_url=site, timeout=30) as client:
        admin = issue(seeded_engine, "admin")
        for hour, engaged in ((0, True), (1, False)):
            start = evening + timedelta(hours=hour)
            post_pings(
                client,
                admin,
                drive("SF-002", start, 1000.0, 0.1, 3600, controller_engaged=engaged),
            )
    with logged_in(site, "viewer") as client:
        history = client.get("/vehicles/SF-002/history/live").text
    days = re.search(r'data-field="engagement">engaged per day \(([^)]+)\): ([^<]*)</p>', history)
    assert days is not None, history
    assert days.group(1) == zone.key
    assert days.group(2).split(" · ") == [f"{yesterday:%m-%d} 50 %"]


def test_the_csrf_token_belongs_to_the_session(site: str) -> None:
    with logged_in(site, "operator") as first, logged_in(site, "operator") as second:
        assert csrf_of(first.get("/fleet").text) != csrf_of(second.get("/fleet").text)


# --- policies -----------------------------------------------------------------------------------


def test_the_fleet_and_vehicle_pages_show_the_policy_each_car_runs(
    site: str, seeded_engine: Engine
) -> None:
    first, second = "ab" * 32, "cd" * 32
    shipped = "e530c072f540c1af93d1878abc9f46e61ad334692b0245782abeedbba62ba6df"  # SF-099's
    now = datetime.now(UTC).replace(microsecond=0)
    with httpx.Client(base_url=site, timeout=30) as api:
        admin = issue(seeded_engine, "admin")
        # SF-001 and SF-002 are assigned microaccel_acc (the seed) and last ran RL policies;
        # SF-099 runs the rl_accel policy its assignment names
        for vehicle_id, controller, policy in (
            ("SF-001", "rl_acc", first),
            ("SF-002", "rl_acc", second),
            ("SF-099", "rl_accel", shipped),
        ):
            pings = drive(vehicle_id, now - timedelta(seconds=5), 3000.0, 25.0, 5)
            post_pings(
                api,
                admin,
                [{**ping, "controller": controller, "policy_sha256": policy} for ping in pings],
            )
        post_status(
            api, admin, "SF-001", **healthy_status(now - timedelta(seconds=2)), policy_sha256=first
        )
    with logged_in(site, "viewer") as client:
        fleet = client.get("/fleet").text
        vehicle = client.get("/vehicles/SF-001").text

    def ran(policy: str) -> str:
        return (
            '<span class="reported" data-field="reported">(last ping ran rl_acc <code '
            f'class="policy" data-field="policy" title="last ping ran policy {policy}">'
            f"{policy[:12]}</code>)</span>"
        )

    # the policy sits beside the controller that ran it, not the one assigned since
    assert '<span data-field="controller">microaccel_acc</span> ' + ran(first) in fleet
    assert '<span data-field="controller">microaccel_acc</span> ' + ran(second) in fleet
    assert '<span data-field="controller">microaccel_acc</span> ' + ran(first) in vehicle
    assert f'<code class="policy" title="{first}">{first[:12]}</code>' in vehicle  # status history
    # a car running what it is assigned says it once
    row = fleet[fleet.index('data-vehicle="SF-099"') :]
    row = row[: row.index("</tr>")]
    assert (
        '<span data-field="controller">rl_accel</span> <code class="policy" '
        f'data-field="assigned-policy" title="assigned policy {shipped}">{shipped[:12]}</code></td>'
    ) in row
    assert 'data-field="reported"' not in row


def test_a_car_on_the_bundled_policy_is_not_shown_as_running_something_else(
    site: str, seeded_engine: Engine
) -> None:
    """An RL assignment naming no policy runs the agent's bundled one: its pings report that
    hash, which the row compared with no policy at all, "(last ping ran rl_acc ...)"."""
    bundled = hashlib.sha256((BUNDLED_POLICIES / "rl_acc.npz").read_bytes()).hexdigest()
    now = datetime.now(UTC).replace(microsecond=0)
    with httpx.Client(base_url=site, timeout=30) as api:
        admin = issue(seeded_engine, "admin")
        assigned = api.put(
            "/api/v1/vehicles/SF-081/assignment",
            json={"lane": 1, "route": "A", "controller": {"name": "rl_acc", "params": {}}},
            headers=bearer(admin),
        )
        assert assigned.status_code == 200, assigned.text
        pings = drive("SF-081", now - timedelta(seconds=5), 3000.0, 25.0, 5)
        post_pings(
            api,
            admin,
            [{**ping, "controller": "rl_acc", "policy_sha256": bundled} for ping in pings],
        )
    with logged_in(site, "viewer") as client:
        fleet = client.get("/fleet").text
    row = fleet[fleet.index('data-vehicle="SF-081"') :]
    row = row[: row.index("</tr>")]
    assert (
        '<span data-field="controller">rl_acc</span> <code class="policy" '
        f'data-field="assigned-policy" title="the agent\'s bundled policy {bundled}">'
        f"{bundled[:12]}</code></td>"
    ) in row
    assert 'data-field="reported"' not in row


def test_in_maintenance_since_names_who_took_the_car_out_not_who_edited_the_note(
    site: str,
) -> None:
    """Every save is a change: the page read the newest maintenance change as the one that took
    the car out, so an admin who only extended the note was named, at the edit's time, and
    after ten more changes "since ... by" was gone."""
    with logged_in(site, "operator") as operator, logged_in(site, "admin") as admin:
        out = post_form(
            operator,
            "/vehicles/SF-041",
            "/vehicles/SF-041/maintenance",
            in_maintenance="on",
            note="brake light out",
        )
        assert out.status_code == 303
        for edit in range(11):
            edited = post_form(
                admin,
                "/vehicles/SF-041",
                "/vehicles/SF-041/maintenance",
                in_maintenance="on",
                note=f"brake light out; part ordered ({edit})",
            )
            assert edited.status_code == 303
        page = admin.get("/vehicles/SF-041").text
        assert re.search(
            r"in maintenance since [^<]+ by dashboard user operator: brake light out; part "
            r"ordered \(10\)",
            page,
        )
        assert "maintenance note now: brake light out; part ordered (10)" in page
        assert "taken out for maintenance" not in page  # beyond the ten newest changes
