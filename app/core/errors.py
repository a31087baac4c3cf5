"""One error shape for the whole API, and the database-outage answer.

Every error body is `{"detail": "<what was wrong>"}` (422 keeps FastAPI's list of field errors
under the same key). A database that cannot be reached is a 503 with Retry-After, never a 500:
vehicles then keep their pings spooled and retry.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.responses import JSONResponse
from pydantic import BaseModel
from sqlalchemy.exc import DBAPIError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError

log = logging.getLogger(__name__)

RETRY_AFTER_S = 5


class ErrorResponse(BaseModel):
    """The body of every non-validation error."""

    detail: str


def error_responses(*codes: int) -> dict[int | str, dict[str, Any]]:
    """OpenAPI `responses=` entries declaring the error shape for the given status codes."""
    descriptions = {
        401: "missing or invalid bearer token",
        403: "the token may not do this",
        404: "not found",
        409: "conflict",
        413: "request body too large",
        429: "too many requests",
        503: "database unavailable or nothing valid to serve; retry after Retry-After",
    }
    return {
        code: {"model": ErrorResponse, "description": descriptions.get(code, "error")}
        for code in codes
    }


def service_unavailable(detail: str, retry_after_s: int = RETRY_AFTER_S) -> JSONResponse:
    """A 503 in the API's error shape."""
    return JSONResponse(
        {"detail": detail}, status_code=503, headers={"Retry-After": str(retry_after_s)}
    )


def _is_outage(error: DBAPIError) -> bool:
    return isinstance(error, OperationalError | InterfaceError) or bool(
        getattr(error, "connection_invalidated", False)
    )


def install_error_handlers(app: FastAPI) -> None:
    """Map database outages to 503 instead of 500."""

    async def on_pool_timeout(request: Request, error: Exception) -> JSONResponse:
        log.warning("database pool exhausted or unreachable: %s", error)
        return service_unavailable("database unavailable, retry later")

    async def on_dbapi_error(request: Request, error: Exception) -> JSONResponse:
        assert isinstance(error, DBAPIError)
        if _is_outage(error):
            log.warning("database unavailable: %s", str(error).splitlines()[0])
            return service_unavailable("database unavailable, retry later")
        raise error

    async def on_os_error(request: Request, error: Exception) -> JSONResponse:
        log.warning("database connection failed: %s", error)
        return service_unavailable("database unavailable, retry later")

    app.add_exception_handler(PoolTimeoutError, on_pool_timeout)
    app.add_exception_handler(DBAPIError, on_dbapi_error)
    app.add_exception_handler(ConnectionError, on_os_error)
