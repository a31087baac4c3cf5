"""A dashboard session ends after SMOOTHFLEET_DASHBOARD_SESSION_IDLE_S without the user doing
anything; a page refreshing itself is not the user doing something.

Before, a session lived its 12 h whatever happened: a dashboard left open on an unattended desk
stayed an operator's (with the rights to reassign cars) until then.
"""

from __future__ import annotations

import time
from collections.abc import Iterator

import pytest
from sqlalchemy import Engine

from app.core.config import load_settings
from dashboards.auth import SESSION_COOKIE
from tests.dashboards.support import add_users, csrf_of, logged_in
from tests.support.servers import live_server

IDLE_S = 2.0
LIVE = {"X-Requested-With": "fetch"}


def test_a_cookie_idle_past_the_limit_is_no_session_though_within_its_age() -> None:
    from dashboards.auth import new_session, read_session_cookie, session_cookie

    settings = load_settings()
    assert settings.dashboard_session_idle_s == 3600.0
    assert settings.dashboard_session_max_age_s == 43200.0
    issued = 1_000_000.0
    cookie = session_cookie(settings, new_session("viewer", "scrypt$x", issued))
    assert read_session_cookie(settings, cookie, issued + 3599) is not None
    assert read_session_cookie(settings, cookie, issued + 3601) is None


@pytest.fixture
def idle_site(seeded_database_url: str, seeded_engine: Engine) -> Iterator[str]:
    add_users(seeded_engine)
    with live_server(
        seeded_database_url, planner_enabled=False, dashboard_session_idle_s=IDLE_S
    ) as base:
        yield base


def test_a_session_left_idle_ends_and_one_in_use_goes_on(idle_site: str) -> None:
    with logged_in(idle_site, "operator") as idle, logged_in(idle_site, "operator") as busy:
        for _ in range(4):  # twice the idle limit, a page every half of it
            time.sleep(IDLE_S / 2)
            assert busy.get("/fleet").status_code == 200
        left = idle.get("/fleet")
        assert left.status_code == 303
        assert left.headers["location"].startswith("/login")


def test_a_page_refreshing_itself_does_not_keep_its_session_alive(idle_site: str) -> None:
    """The fleet page refreshes its table every few seconds on its own: were that activity, a
    page left open would never be idle. Once the user has done nothing for the idle limit, the
    next refresh is told to log in again (the page's script then goes to the login form)."""
    with logged_in(idle_site, "viewer") as client:
        assert client.get("/fleet").status_code == 200
        time.sleep(IDLE_S / 2)
        refreshed = client.get("/fleet/live", headers=LIVE)
        assert refreshed.status_code == 200
        assert SESSION_COOKIE not in refreshed.headers.get("set-cookie", "")
        time.sleep(IDLE_S / 2 + 0.3)
        ended = client.get("/fleet/live", headers=LIVE)
    assert ended.status_code == 401
    assert ended.json() == {"detail": "log in again"}


def test_logging_out_deletes_the_cookie_the_request_renewed(idle_site: str) -> None:
    """Every page renews the session cookie; the logout's deletion must be the last word."""
    with logged_in(idle_site, "viewer") as client:
        response = client.post("/logout", data={"csrf_token": csrf_of(client.get("/fleet").text)})
        assert response.status_code == 303
        assert client.cookies.get(SESSION_COOKIE) is None
