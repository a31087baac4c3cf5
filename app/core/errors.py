"""One error shape for the whole API, and the database-outage answer.

Every error body is `{"detail": "<what was wrong>"}` (422 keeps FastAPI's list of field errors
under the same key). A database that cannot be reached is a 503 with Retry-After, never a 500:
vehicles then keep their pings spooled and retry.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Mapping
from typing import Any

from fastapi import FastAPI, Request, Response
from fastapi.exception_handlers import http_exception_handler
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from sqlalchemy.exc import DataError, DBAPIError, InterfaceError, OperationalError
from sqlalchemy.exc import TimeoutError as PoolTimeoutError
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.core.body_limit import BodyTooLarge
from app.core.json_keys import REPEATED_KEY
from app.core.logs import RepeatedMessages
from contract.errors import DATABASE_UNAVAILABLE, ErrorCode, ErrorResponse

log = logging.getLogger(__name__)
log.addFilter(RepeatedMessages())  # an outage is one line a window, not one a request

RETRY_AFTER_S = 5


def content_encoding_refusal(content_encoding: str | None) -> str | None:
    """Why a body sent with this Content-Encoding cannot be read (None: it can). The service
    takes bodies as they are: a compressed one was read as text and refused as "not valid
    UTF-8" (pings) or "Input should be a valid dictionary" (the other JSON bodies), which
    named no cause."""
    coding = (content_encoding or "").strip().lower()
    if coding in ("", "identity"):
        return None
    return f"Content-Encoding {coding} is not accepted; send the body uncompressed"


def _unread_body(headers: Mapping[str, str]) -> str | None:
    """Why a JSON body was not read as JSON, when the request says so in its headers (None:
    it does not). FastAPI reads a body as JSON only under a JSON content type, and a form's
    body then failed as "Input should be a valid dictionary", which named no cause."""
    refusal = content_encoding_refusal(headers.get("content-encoding"))
    if refusal is not None:
        return refusal
    media = headers.get("content-type", "").split(";")[0].strip().lower()
    if media and media != "application/json" and not media.endswith("+json"):
        return f"the body must be JSON sent as Content-Type: application/json (not {media})"
    return None


def error_responses(
    *codes: int, described: Mapping[int, str] | None = None
) -> dict[int | str, dict[str, Any]]:
    """OpenAPI `responses=` entries declaring the error shape for the given status codes.

    422 is always declared: any request can be malformed, and its body has this same shape; so
    is 429 wherever a token is needed (app/core/ratelimit.py). `described` says what a code
    means on this operation, where the general description would not.
    """
    codes = tuple(sorted({*codes, 422, *((429,) if 401 in codes else ())}))
    descriptions = {
        401: "missing or invalid bearer token",
        403: "the token may not do this",
        404: "not found",
        409: "conflict",
        422: "malformed request: a sentence, or the list of rejected fields",
        413: "request body too large",
        429: "too many requests",
        503: "database unavailable or nothing valid to serve; retry after Retry-After",
    }
    descriptions.update(described or {})
    return {
        code: {"model": ErrorResponse, "description": descriptions.get(code, "error")}
        for code in codes
    }


def service_unavailable(
    detail: str, retry_after_s: int = RETRY_AFTER_S, code: ErrorCode = DATABASE_UNAVAILABLE
) -> JSONResponse:
    """A 503 in the API's error shape, with the code that tells a car what it means."""
    return JSONResponse(
        {"detail": detail, "code": code},
        status_code=503,
        headers={"Retry-After": str(retry_after_s)},
    )


def _is_outage(error: DBAPIError) -> bool:
    return isinstance(error, OperationalError | InterfaceError) or bool(
        getattr(error, "connection_invalidated", False)
    )


def is_database_outage(error: BaseException) -> bool:
    """True when `error` says the database cannot be reached (not that a statement is wrong)."""
    if isinstance(error, DBAPIError):
        return _is_outage(error)
    return isinstance(error, PoolTimeoutError | ConnectionError)


HTTP_METHODS = frozenset({"get", "put", "post", "delete", "options", "head", "patch", "trace"})


def _template_pattern(template: str) -> re.Pattern[str]:
    """A regex for an OpenAPI path template (`/api/v1/policies/{sha256}`)."""
    parts = re.split(r"(\{[^}/]+\})", template)
    return re.compile(
        "".join("[^/]+" if part.startswith("{") else re.escape(part) for part in parts)
    )


def allowed_methods(request: Request, fallback: str) -> str:
    """Every method the API documents for the request's path, for a 405's Allow header.

    Starlette's 405 names only the methods of the first route on the path, so a path served by
    one route per method (GET /api/v1/policies to list, POST to upload) would advertise less
    than it serves. Paths outside the document (the dashboard) keep Starlette's `fallback`.
    """
    path = request.scope["path"]
    methods = {
        method.upper()
        for template, operations in request.app.openapi()["paths"].items()
        if _template_pattern(template).fullmatch(path)
        for method in operations
        if method in HTTP_METHODS
    }
    return ", ".join(sorted(methods)) if methods else fallback


def install_error_handlers(app: FastAPI) -> None:
    """Database outages are 503, undecodable bodies and unstorable values 422, never 500."""

    async def on_http_error(request: Request, error: Exception) -> Response:
        assert isinstance(error, StarletteHTTPException)
        if isinstance(error.__cause__, BodyTooLarge):
            # FastAPI wraps what stopped it reading the body in a 400: a chunked body cut off
            # at the limit is the body-size middleware's 413, as a declared length over it is
            raise error.__cause__
        if error.status_code == 400 and isinstance(error.__cause__, ValueError):
            # FastAPI answers a body it cannot decode with a 400 raised from what failed (text
            # that is not UTF-8 is a UnicodeDecodeError, an over-long integer a ValueError); the
            # interface promises 422 for a body that is not the expected JSON at all
            why = _unread_body(request.headers)
            # FastAPI answers a JSON syntax error itself (422); what reaches here failed after
            # the syntax: text that is not UTF-8, or an integer Python will not read
            detail = (
                f"request body cannot be read: {why}"
                if why
                else "request body cannot be read as JSON: it is not UTF-8 text, or holds an "
                "integer too long to read (over 4,300 digits)"
            )
            return JSONResponse({"detail": detail}, 422)
        if error.status_code == 400:
            # Starlette's answer to a multipart or form body it cannot parse (the reason is
            # python-multipart's): as unreadable as bad JSON, so the same 422.
            return JSONResponse({"detail": f"request body cannot be read: {error.detail}"}, 422)
        if error.status_code == 405:
            fallback = (error.headers or {}).get("Allow", "")
            return JSONResponse(
                {"detail": "Method Not Allowed"},
                405,
                headers={"Allow": allowed_methods(request, fallback)},
            )
        return await http_exception_handler(request, error)

    async def on_pool_timeout(request: Request, error: Exception) -> JSONResponse:
        log.warning("database pool exhausted or unreachable: %s", error)
        return service_unavailable("database unavailable, retry later")

    async def on_dbapi_error(request: Request, error: Exception) -> JSONResponse:
        assert isinstance(error, DBAPIError)
        if _is_outage(error):
            log.warning("database unavailable: %s", str(error).splitlines()[0])
            return service_unavailable("database unavailable, retry later")
        if isinstance(error, DataError):
            # e.g. a NUL character, which PostgreSQL text cannot hold: the input's fault.
            reason = str(error.orig).strip().splitlines()[0] if error.orig else "invalid value"
            return JSONResponse({"detail": f"a value cannot be stored: {reason}"}, 422)
        raise error

    async def on_os_error(request: Request, error: Exception) -> JSONResponse:
        log.warning("database connection failed: %s", error)
        return service_unavailable("database unavailable, retry later")

    async def on_invalid_request(request: Request, error: Exception) -> JSONResponse:
        assert isinstance(error, RequestValidationError)
        # Each field error as FieldError says it (where, what, which rule), without the
        # rejected input: it may be what made the request invalid (a NaN, a lone surrogate)
        # and cannot always be written back as JSON.
        fields = [
            {"loc": list(item["loc"]), "msg": item["msg"], "type": item["type"]}
            for item in error.errors()
        ]
        whole_body = next(
            (
                field
                for field in fields
                if field["loc"] == ["body"] and field["type"] != REPEATED_KEY
            ),
            None,
        )
        if whole_body is not None:
            why = _unread_body(request.headers)
            if why is not None:
                whole_body["msg"] = why
        return JSONResponse({"detail": fields}, 422)

    app.add_exception_handler(StarletteHTTPException, on_http_error)
    app.add_exception_handler(RequestValidationError, on_invalid_request)
    app.add_exception_handler(PoolTimeoutError, on_pool_timeout)
    app.add_exception_handler(DBAPIError, on_dbapi_error)
    app.add_exception_handler(ConnectionError, on_os_error)
