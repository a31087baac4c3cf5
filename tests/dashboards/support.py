"""A logged-in dashboard client for the page tests and the browser tests."""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import httpx
from sqlalchemy import Engine

from app.core.db import session_scope
from app.users.service import save_user

CSRF = re.compile(r'name="csrf_token" value="([^"]+)"')
PASSWORDS = {
    "viewer": "viewer-password-1",
    "operator": "operator-password-1",
    "admin": "admin-pass-1",
}


def add_users(engine: Engine) -> None:
    """One user per role, named after the role."""
    with session_scope(engine) as session:
        for role, password in PASSWORDS.items():
            save_user(session, role, role, password)


def csrf_of(html: str) -> str:
    """The first CSRF token of a page's forms."""
    found = CSRF.search(html)
    assert found, "no CSRF token on the page"
    return found.group(1)


def log_in(
    client: httpx.Client, username: str, password: str, next_path: str = "/fleet"
) -> httpx.Response:
    """Fill in the login form the way a browser does."""
    form = client.get("/login", params={"next": next_path})
    return client.post(
        "/login",
        data={
            "username": username,
            "password": password,
            "csrf_token": csrf_of(form.text),
            "next": next_path,
        },
    )


@contextmanager
def logged_in(base_url: str, role: str) -> Iterator[httpx.Client]:
    """A client holding a session of the user of `role`."""
    with httpx.Client(base_url=base_url, timeout=30) as client:
        response = log_in(client, role, PASSWORDS[role])
        assert response.status_code == 303, response.text
        yield client


def post_form(client: httpx.Client, page: str, action: str, **fields: Any) -> httpx.Response:
    """Submit a form of `page` with that page's CSRF token (unless one is given)."""
    fields.setdefault("csrf_token", csrf_of(client.get(page).text))
    return client.post(action, data=fields)
