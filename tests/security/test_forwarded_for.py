"""X-Forwarded-For is believed only from the proxies named in SMOOTHFLEET_TRUSTED_PROXIES.

Otherwise any client could rotate the header and meet no per-address login limit.
"""

from __future__ import annotations

import httpx
import pytest
from sqlalchemy import Engine

from tests.dashboards.support import add_users, csrf_of
from tests.support.servers import live_server

ATTEMPTS = 25
PER_MINUTE = 10


def login_statuses(base: str) -> list[int]:
    """Failed logins, each claiming another client address in X-Forwarded-For."""
    statuses = []
    for n in range(ATTEMPTS):
        headers = {"X-Forwarded-For": f"203.0.113.{n + 1}"}
        with httpx.Client(base_url=base, headers=headers) as client:
            form = client.get("/login")
            answer = client.post(
                "/login",
                data={
                    "username": f"nobody-{n}",  # a new account each time: no per-account wait
                    "password": "guess-guess",
                    "csrf_token": csrf_of(form.text),
                },
            )
            statuses.append(answer.status_code)
    return statuses


@pytest.mark.parametrize(
    ("trusted_proxies", "limited"),
    [("", True), ("10.9.8.7", True), ("127.0.0.1", False)],
    ids=["no-proxy-trusted", "another-proxy-trusted", "this-peer-trusted"],
)
def test_rotated_forwarded_addresses_meet_the_login_limit_unless_the_peer_is_trusted(
    seeded_database_url: str, seeded_engine: Engine, trusted_proxies: str, limited: bool
) -> None:
    add_users(seeded_engine)
    with live_server(
        seeded_database_url,
        planner_enabled=False,
        trusted_proxies=trusted_proxies,
        login_attempts_per_minute=PER_MINUTE,
    ) as base:
        statuses = login_statuses(base)
    if limited:  # one client: the limit's burst, then mostly refusals (it refills 1 per 6 s)
        assert statuses[:PER_MINUTE] == [401] * PER_MINUTE
        assert statuses.count(429) >= ATTEMPTS // 2, statuses
    else:  # a trusted proxy's word: each address is its own client
        assert statuses == [401] * ATTEMPTS
