"""Login limits count an IPv6 client by its /64, an IPv4 one by its address.

Counted by full IPv6 address, a client rotating addresses within its /64 (one customer's
prefix) met a fresh allowance with each one; text that is no address was a fresh allowance per
spelling, and a few kilobytes of it a 503.
"""

from __future__ import annotations

import logging
import secrets

import httpx
import pytest
from sqlalchemy import Engine, text

from app.users.client_key import UNREADABLE_CLIENT, login_client_key
from tests.dashboards.support import PASSWORDS, add_users, log_in
from tests.support.servers import cli_env, live_server, run_cli


@pytest.mark.parametrize(
    ("address", "key"),
    [
        ("203.0.113.9", "203.0.113.9"),
        ("2001:db8:bad:1::1", "2001:db8:bad:1::/64"),
        ("2001:db8:bad:1:ffff:ffff:ffff:ffff", "2001:db8:bad:1::/64"),
        ("2001:0DB8:0BAD:0001:0000:0000:0000:0009", "2001:db8:bad:1::/64"),
        ("2001:db8:bad:2::1", "2001:db8:bad:2::/64"),
        ("::ffff:203.0.113.9", "203.0.113.9"),
        ("::ffff:cb00:7109", "203.0.113.9"),
        # IPv4 clients translated (NAT64) or tunnelled (Teredo) to IPv6: each its own client,
        # not one /64 for everyone behind the translator or relay
        ("64:ff9b::c000:207", "192.0.2.7"),
        ("64:ff9b::c633:6401", "198.51.100.1"),
        ("2001:0:4136:e378:8000:63bf:3fff:fdd2", "192.0.2.45"),
        ("2001:0:4136:e378:8000:63bf:1234:5678", "237.203.169.135"),
        ("::1", "::/64"),
        ("fe80::1%eth0", "fe80::/64"),
    ],
)
def test_a_client_is_its_ipv4_address_or_its_ipv6_slash_64(address: str, key: str) -> None:
    assert login_client_key(address) == key


@pytest.mark.parametrize(
    "address",
    [
        None,
        "",
        "unknown",
        "testclient",
        "203.0.113.256",
        "203.0.113.9:8080",
        "[2001:db8::1]",
        "2001:db8::1/64",
        "2001:db8:::1",
        "203.0.113.9 ",
        "x" * 5000,
    ],
)
def test_an_address_that_is_no_ip_address_is_the_one_unreadable_client(
    address: str | None,
) -> None:
    assert login_client_key(address) == UNREADABLE_CLIENT


def test_the_unreadable_client_is_no_ip_address_of_its_own() -> None:
    assert login_client_key(UNREADABLE_CLIENT) == UNREADABLE_CLIENT


def failures_of(engine: Engine, username: str) -> list[tuple[str, int]]:
    with engine.connect() as connection:
        rows = connection.execute(
            text(
                "SELECT client_address, failures FROM ops_login_failure WHERE username = :u "
                "ORDER BY client_address"
            ),
            {"u": username},
        ).all()
    return [(str(row[0]), int(row[1])) for row in rows]


def log_in_from(base: str, forwarded_for: str, username: str, password: str) -> httpx.Response:
    """A login through the trusted proxy (this test's peer) for the client it names."""
    with httpx.Client(base_url=base, headers={"X-Forwarded-For": forwarded_for}) as client:
        return log_in(client, username, password)


def test_an_ipv6_client_rotating_within_its_slash_64_waits_and_the_owner_does_not(
    seeded_database_url: str, seeded_engine: Engine, caplog: pytest.LogCaptureFixture
) -> None:
    """Each failure from a new address of one /64: the fourth attempt waits as from one
    address; the owner on another /64 is let in, and `users list` and the log name the /64."""
    add_users(seeded_engine)
    with (
        caplog.at_level(logging.INFO, logger="app.users"),
        live_server(
            seeded_database_url, planner_enabled=False, trusted_proxies="127.0.0.1"
        ) as base,
    ):
        for n in range(1, 4):
            assert (
                log_in_from(base, f"2001:db8:bad:1::{n}", "admin", "guess-guess").status_code == 401
            )
        waiting = log_in_from(base, "2001:db8:bad:1:9:9:9:9", "admin", PASSWORDS["admin"])
        assert waiting.status_code == 429
        assert waiting.headers["retry-after"] == "1"
        owner = log_in_from(base, "2001:db8:600d:2::7", "admin", PASSWORDS["admin"])
        assert owner.status_code == 303
    assert failures_of(seeded_engine, "admin") == [("2001:db8:bad:1::/64", 3)]
    logged = [
        record.getMessage() for record in caplog.records if record.name == "app.users.service"
    ]
    assert any("'admin'" in line and "2001:db8:bad:1::/64" in line for line in logged), logged
    assert not any("2001:db8:bad:1::1" in line for line in logged), logged

    listed = run_cli("users", "list", env=cli_env(SMOOTHFLEET_DATABASE_URL=seeded_database_url))
    assert listed.returncode == 0, listed.stderr
    assert "2001:db8:bad:1::/64" in listed.stdout
    assert "2001:db8:bad:1::1" not in listed.stdout


def test_an_ipv4_client_is_one_client_however_its_address_is_written(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """A dual-stack proxy reports an IPv4 peer as `::ffff:a.b.c.d`: that is the same client
    as `a.b.c.d`, not a /64 of its own; and IPv4 neighbours are clients of their own."""
    add_users(seeded_engine)
    with live_server(
        seeded_database_url, planner_enabled=False, trusted_proxies="127.0.0.1"
    ) as base:
        for address in ("::ffff:203.0.113.9", "203.0.113.9", "::ffff:203.0.113.9"):
            assert log_in_from(base, address, "operator", "guess-guess").status_code == 401
        assert (
            log_in_from(base, "203.0.113.9", "operator", PASSWORDS["operator"]).status_code == 429
        )
        assert (
            log_in_from(base, "203.0.113.10", "operator", PASSWORDS["operator"]).status_code == 303
        )
    assert failures_of(seeded_engine, "operator") == [("203.0.113.9", 3)]


def test_a_forwarded_for_that_is_no_address_is_one_client_and_no_error(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Kept as sent, every spelling was a client of its own, and 3,200 characters of one were
    more than the index on ops_login_failure takes: a 503 saying the database was down."""
    add_users(seeded_engine)
    with live_server(
        seeded_database_url, planner_enabled=False, trusted_proxies="127.0.0.1"
    ) as base:
        # random text, which PostgreSQL cannot compress to fit the index
        for spelling in ("unknown", secrets.token_urlsafe(2400), "_hidden"):
            answer = log_in_from(base, spelling, "viewer", "guess-guess")
            assert answer.status_code == 401, answer.text[:200]
        assert log_in_from(base, "obfuscated", "viewer", PASSWORDS["viewer"]).status_code == 429
        assert log_in_from(base, "198.51.100.7", "viewer", PASSWORDS["viewer"]).status_code == 303
    assert failures_of(seeded_engine, "viewer") == [(UNREADABLE_CLIENT, 3)]


def test_addresses_of_one_slash_64_share_the_attempts_per_minute(
    seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Made-up usernames (no per-account wait), each attempt from a new address of one /64:
    the per-minute limit's burst, then refusals, as from one address."""
    add_users(seeded_engine)
    per_minute = 10
    with live_server(
        seeded_database_url,
        planner_enabled=False,
        trusted_proxies="127.0.0.1",
        login_attempts_per_minute=per_minute,
    ) as base:
        statuses = [
            log_in_from(base, f"2001:db8:bad:1::{n:x}", f"nobody-{n}", "guess-guess").status_code
            for n in range(1, 16)
        ]
        other_prefix = log_in_from(base, "2001:db8:bad:2::1", "nobody", "guess-guess")
    assert statuses[:per_minute] == [401] * per_minute
    assert statuses[per_minute:].count(429) >= 4, statuses
    assert other_prefix.status_code == 401
