"""Dashboard users (table ops_user): salted scrypt passwords and a login that slows down guessing.

A wrong password (or unknown username) counts against the account *from that client* (table
ops_login_failure), a client being its key from `app.users.client_key`: an IPv4 address or an
IPv6 /64. From the third failure in a row there, that client must wait 1, 2, 4, ... s (at most
LOCKOUT_MAX_S) after its last failure before another attempt from it is even checked. A success
resets that client's count. Counted per account alone, a stranger's one wrong guess every five
minutes kept the owner out for good (a security audit); per (account, client), the stranger
waits and the owner, elsewhere, does not. Guessing from many clients meets the dashboard's
per-client limit on each; it slows nothing more, and shows in the account's count
(`failed_logins`, `smoothfleet users list`), every client's failures since the account's last
success. A username that is no account is counted and made to wait the same
way, in the server process's memory: the answers do not tell which usernames exist. With
several workers a made-up name's count is per worker, so its waits can come later than an
account's.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import logging
import math
import re
import secrets
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Literal

import anyio.to_thread
from sqlalchemy import delete, literal_column, select, update
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.ext.asyncio import AsyncSession
from sqlalchemy.orm import Session

from app.models import OpsLoginFailure, OpsUser

log = logging.getLogger(__name__)

OpsRole = Literal["viewer", "operator", "admin"]
OPS_ROLES: tuple[OpsRole, ...] = ("viewer", "operator", "admin")
USERNAME_PATTERN = re.compile(r"^[A-Za-z0-9_.@-]{1,64}$")
MIN_PASSWORD_LENGTH = 10

# scrypt cost: n = 2^14, r = 8 uses 16 MiB and ~50 ms per hash on a Raspberry-Pi-class core, the
# interactive-login setting recommended by the scrypt paper.
SCRYPT_N = 2**14
SCRYPT_R = 8
SCRYPT_P = 1
SCRYPT_KEY_BYTES = 32
SALT_BYTES = 16

FREE_FAILURES = 2  # failures before an (account, client) starts waiting between attempts
LOCKOUT_MAX_S = 300.0


class UserError(ValueError):
    """A username, role or password that cannot be stored; the message says which."""


def _b64(data: bytes) -> str:
    return base64.b64encode(data).decode("ascii")


def hash_password(password: str) -> str:
    """`scrypt$n$r$p$salt$key` with a fresh random salt."""
    salt = secrets.token_bytes(SALT_BYTES)
    key = hashlib.scrypt(
        password.encode(), salt=salt, n=SCRYPT_N, r=SCRYPT_R, p=SCRYPT_P, dklen=SCRYPT_KEY_BYTES
    )
    return f"scrypt${SCRYPT_N}${SCRYPT_R}${SCRYPT_P}${_b64(salt)}${_b64(key)}"


def verify_password(password: str, stored: str) -> bool:
    """Whether the password matches the stored hash (constant-time comparison)."""
    try:
        scheme, n, r, p, salt, key = stored.split("$")
        if scheme != "scrypt":
            return False
        expected = base64.b64decode(key)
        candidate = hashlib.scrypt(
            password.encode(),
            salt=base64.b64decode(salt),
            n=int(n),
            r=int(r),
            p=int(p),
            dklen=len(expected),
        )
    except (ValueError, TypeError):
        return False
    return hmac.compare_digest(candidate, expected)


# Checked against when the username is unknown, so both failures take the same time.
_DUMMY_HASH = hash_password(secrets.token_urlsafe(16))


def check_new_user(username: str, role: str, password: str) -> None:
    """Raise UserError naming what is wrong with a user about to be stored."""
    if not USERNAME_PATTERN.match(username):
        raise UserError("username: 1-64 letters, digits or _ . @ -")
    if role not in OPS_ROLES:
        raise UserError(f"role: must be one of {', '.join(OPS_ROLES)}, not {role!r}")
    if len(password) < MIN_PASSWORD_LENGTH:
        raise UserError(f"password: at least {MIN_PASSWORD_LENGTH} characters")


def save_user(session: Session, username: str, role: str, password: str) -> bool:
    """Create the user, or reset its role and password (which ends every client's wait on it:
    the admin's way to let a user in); True when it was created."""
    check_new_user(username, role, password)
    statement = insert(OpsUser).values(
        username=username, role=role, password_hash=hash_password(password)
    )
    statement = statement.on_conflict_do_update(
        index_elements=[OpsUser.username],
        set_={
            "role": statement.excluded.role,
            "password_hash": statement.excluded.password_hash,
            "failed_logins": 0,
            "last_failed_at": None,
        },
    )
    # xmax = 0 on the returned row means it was inserted rather than updated (PostgreSQL).
    created = bool(session.execute(statement.returning(literal_column("xmax = 0"))).scalar_one())
    session.execute(delete(OpsLoginFailure).where(OpsLoginFailure.username == username))
    return created


def new_password() -> str:
    """A random password to print once (the demo's admin)."""
    return secrets.token_urlsafe(12)


def wait_before_next_attempt(failures: int) -> float:
    """Seconds a client must wait after its last failure on an account: 0, then 1, 2, 4, ...
    up to the cap."""
    if failures <= FREE_FAILURES:
        return 0.0
    # the exponent is bounded before the power: 2.0 ** 1100 overflows, and a count that large
    # (days of one address guessing one account) turned the login into a 500
    doublings = min(failures - FREE_FAILURES - 1, math.ceil(math.log2(LOCKOUT_MAX_S)))
    return float(min(2.0**doublings, LOCKOUT_MAX_S))


@dataclass(frozen=True)
class LoginResult:
    """The outcome of a login attempt: the user, or a message and how long to wait."""

    user: OpsUser | None
    message: str = ""
    retry_after_s: float = 0.0


WRONG_CREDENTIALS = "Wrong username or password."

# Failures of usernames that are no account, per (username, client) and server process, as an
# account's are counted in ops_login_failure: if only real accounts slowed down, three bad
# guesses would tell which usernames exist. Bounded, so guessing many names cannot grow the
# process: past the bound it starts over.
MAX_UNKNOWN_USERNAMES = 10_000
_unknown_failures: dict[tuple[str, str], tuple[int, datetime]] = {}


def _locked_out(
    failures: int, last_failed_at: datetime | None, now: datetime
) -> LoginResult | None:
    """The answer to an attempt made before the client's wait on the account ran out, or None."""
    if last_failed_at is None:
        return None
    unlocks_at = last_failed_at + timedelta(seconds=wait_before_next_attempt(failures))
    if now >= unlocks_at:
        return None
    wait_s = (unlocks_at - now).total_seconds()
    return LoginResult(
        None,
        "Too many failed logins for this account from this address: "
        f"wait {wait_s:.0f} s and try again.",
        wait_s,
    )


def _log_failure(username: str, client_key: str, failures: int) -> None:
    """One line per failed login, naming the client by the key it is counted under (an IPv6
    client's /64, not the address it used this time), so the log reads as the waits do."""
    log.info(
        "dashboard login failed: user %r from %s (%d in a row from there)",
        username,
        client_key,
        failures,
    )


async def _unknown_username(
    username: str, password: str, client_key: str, now: datetime
) -> LoginResult:
    """Answer as for an account: the same scrypt time, the same count, the same waits."""
    key = (username, client_key)
    failures, last_failed_at = _unknown_failures.get(key, (0, None))
    locked = _locked_out(failures, last_failed_at, now)
    if locked is not None:
        return locked
    await anyio.to_thread.run_sync(verify_password, password, _DUMMY_HASH)
    if len(_unknown_failures) >= MAX_UNKNOWN_USERNAMES:
        _unknown_failures.clear()
    _unknown_failures[key] = (failures + 1, now)
    _log_failure(username, client_key, failures + 1)
    return LoginResult(None, WRONG_CREDENTIALS)


async def log_in(
    session: AsyncSession, username: str, password: str, client_key: str, now: datetime
) -> LoginResult:
    """Check a login from the client `client_key` (`app.users.client_key.login_client_key` of
    its address); failures are counted and slow that client down on this account (the
    account's row is locked, so concurrent attempts count one by one)."""
    if not USERNAME_PATTERN.match(username):
        # no account has such a name; asked of the database, a NUL in it was PostgreSQL's
        # DataError, which the login form showed as the API's JSON 422
        return await _unknown_username(username, password, client_key, now)
    user = await session.scalar(
        select(OpsUser).where(OpsUser.username == username).with_for_update()
    )
    if user is None:
        return await _unknown_username(username, password, client_key, now)
    failed = await session.get(OpsLoginFailure, (username, client_key))
    if failed is not None:
        locked = _locked_out(failed.failures, failed.last_failed_at, now)
        if locked is not None:
            return locked
    # scrypt takes tens of milliseconds: off the event loop.
    if not await anyio.to_thread.run_sync(verify_password, password, user.password_hash):
        if failed is None:
            failed = OpsLoginFailure(
                username=username, client_address=client_key, failures=1, last_failed_at=now
            )
            session.add(failed)
        else:
            failed.failures += 1
            failed.last_failed_at = now
        _log_failure(username, client_key, failed.failures)
        user.failed_logins += 1
        user.last_failed_at = now
        await session.flush()
        return LoginResult(None, WRONG_CREDENTIALS)
    if failed is not None:
        await session.delete(failed)
    user.failed_logins = 0
    user.last_failed_at = None
    user.last_login_at = now
    await session.flush()
    return LoginResult(user)


async def end_sessions(session: AsyncSession, username: str, now: datetime) -> None:
    """End every session of the user issued before `now` (a logout): the dashboard refuses a
    cookie issued before `sessions_valid_from`."""
    await session.execute(
        update(OpsUser).where(OpsUser.username == username).values(sessions_valid_from=now)
    )


def list_users(session: Session) -> list[OpsUser]:
    """Every dashboard user, by name."""
    return list(session.scalars(select(OpsUser).order_by(OpsUser.username)))


def list_login_failures(session: Session) -> list[OpsLoginFailure]:
    """Every (account, client) with failures since its last success, by user and client: who
    is guessing where, as the waits count it."""
    return list(
        session.scalars(
            select(OpsLoginFailure).order_by(
                OpsLoginFailure.username, OpsLoginFailure.client_address
            )
        )
    )
