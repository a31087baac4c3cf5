"""The HTTP answer to `POST /api/v1/pings`, shared by the fast path and the FastAPI route.

Errors keep the API's shape (`{"detail": ...}`): 401 without a valid token, 403 for a token that
may not post pings or a vehicle token carrying another vehicle's ping, 422 for a body that is
not a ping or a batch, 503 + Retry-After when the database is unreachable. Never a 500 for any
of these, and nothing of a refused request is stored.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from datetime import UTC, datetime

import orjson
import psycopg
from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError
from starlette.datastructures import State

from app.auth import CHALLENGE, PING_WRITER_ROLES, bearer_token, token_cache_for
from app.auth.tokens import token_rate_limiter
from app.core.errors import RETRY_AFTER_S, content_encoding_refusal
from app.core.logs import RepeatedMessages
from app.core.ratelimit import retry_after_header
from app.ingest.pings import BodyError, ForeignVehicle
from app.ingest.service import Ingest, RowsRefused
from app.ingest.writer import WriterStopped
from contract.errors import DATABASE_UNAVAILABLE

log = logging.getLogger(__name__)
log.addFilter(RepeatedMessages())  # an outage is one line a window, not one a request

JSON = (b"content-type", b"application/json")
_NEEDED = " or ".join(PING_WRITER_ROLES)


@dataclass(frozen=True, slots=True)
class Reply:
    """Status, JSON body and extra headers of an answer."""

    status: int
    body: bytes
    headers: dict[str, str]


def _error(status: int, detail: str, headers: dict[str, str] | None = None) -> Reply:
    return Reply(status, orjson.dumps({"detail": detail}), headers or {})


def _unavailable(detail: str) -> Reply:
    body = orjson.dumps({"detail": detail, "code": DATABASE_UNAVAILABLE})
    return Reply(503, body, {"Retry-After": str(RETRY_AFTER_S)})


def _is_outage(error: Exception) -> bool:
    # The writer speaks psycopg directly, so its errors come unwrapped.
    outages = (
        PoolTimeoutError,
        OperationalError,
        InterfaceError,
        psycopg.OperationalError,
        psycopg.InterfaceError,
        OSError,
    )
    if isinstance(error, outages):
        return True
    return isinstance(error, DBAPIError) and bool(error.connection_invalidated)


async def reply_to_pings(
    state: State, authorization: str | None, body: bytes, content_encoding: str | None = None
) -> Reply:
    """Authenticate, store the body's good pings (committed), and answer."""
    received_at = datetime.now(UTC)
    token = bearer_token(authorization)
    if token is None:
        return _error(401, "missing bearer token (Authorization: Bearer <token>)", CHALLENGE)
    ingest: Ingest = state.ingest
    try:
        principal = await token_cache_for(state).principal(token)
        if principal is None:
            return _error(401, "invalid or revoked token", CHALLENGE)
        if principal.role not in PING_WRITER_ROLES:
            return _error(403, f"{principal.token_words} may not do this (needs {_NEEDED})")
        wait_s = token_rate_limiter(state).wait_s(principal.token_id)
        if wait_s:
            return _error(429, "too many requests for this token", retry_after_header(wait_s))
        refusal = content_encoding_refusal(content_encoding)
        if refusal is not None:
            return _error(422, f"request body cannot be read: {refusal}")
        result = await ingest.pings(body, principal, received_at)
    except BodyError as error:
        return _error(422, str(error))
    except ForeignVehicle as error:
        return _error(403, str(error))
    except RowsRefused as error:
        return _error(409, str(error))
    except WriterStopped:
        return _unavailable("server shutting down, retry later")
    except Exception as error:
        if not _is_outage(error):
            raise
        log.warning("database unavailable: %s", str(error).splitlines()[0] if str(error) else error)
        return _unavailable("database unavailable, retry later")
    answer = {
        "accepted": result.accepted,
        "duplicates": result.duplicates,
        "conflicts": result.conflicts,
        "rejected": [
            {"index": r.index, "error": r.error, "retryable": r.retryable} for r in result.rejected
        ],
    }
    return Reply(200, orjson.dumps(answer), {})
