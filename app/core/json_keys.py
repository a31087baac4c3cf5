"""JSON bodies in which an object names a key twice are refused, not read by their last value.

Python's json, orjson and pydantic all keep the last value of a repeated key: a ping carrying
"speed_mps" twice was stored with the second speed and its sender never learned the first was
dropped. RFC 8259 leaves such an object's meaning to the receiver, so which value was meant is
unknowable: the body is refused (422), naming the key and where it stands.

The check is one more parse, by jiter (the pydantic team's Rust parser, whose
`catch_duplicate_keys` does exactly this), before the endpoint's own; a Python
`object_pairs_hook` would have cost the ping path about as much again as all its parsing.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Coroutine
from typing import Any

import jiter
from fastapi import Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute
from starlette.requests import ClientDisconnect

# The field error's `type` of a body refused for a repeated key.
REPEATED_KEY = "json_repeated_key"


class RepeatedKey(ValueError):
    """An object of the body names a key twice; the message says which and where."""


def refuse_repeated_keys(body: bytes) -> None:
    """RepeatedKey when an object of the JSON `body` names a key twice.

    A body that is not JSON at all passes: the endpoint's own parser reports what is wrong with
    it. The two jiter parses differ in the duplicate check alone, so a body the strict one
    refuses and the lenient one reads repeats a key. A body jiter cannot read but Python's json
    can (UTF-16 or a byte-order mark, a lone surrogate, nesting past jiter's depth; orjson and
    FastAPI read some of them) is checked by json with a hook: rare, so slow is no matter.
    """
    try:
        jiter.from_json(body, catch_duplicate_keys=True)
    except ValueError as strict:
        try:
            jiter.from_json(body)
        except ValueError:
            _refuse_repeated_keys_slowly(body)
            return
        raise RepeatedKey(f"{strict}: which value is meant is ambiguous") from None


def _object_of_unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """json's `object_pairs_hook`: the object, or RepeatedKey naming the first key it repeats."""
    document = dict(pairs)
    if len(document) != len(pairs):
        seen: set[str] = set()
        for key, _ in pairs:
            if key in seen:
                raise RepeatedKey(
                    f"duplicate key {json.dumps(key)}: which value is meant is ambiguous"
                )
            seen.add(key)
    return document


def _refuse_repeated_keys_slowly(body: bytes) -> None:
    """RepeatedKey when Python's json reads `body` and an object of it repeats a key; nothing
    when json cannot read it either (the endpoint's parser then says what is wrong)."""
    try:
        json.loads(body, object_pairs_hook=_object_of_unique_keys)
    except RepeatedKey:
        raise
    except (ValueError, RecursionError):
        return


class RepeatedKeysRefused(APIRoute):
    """A route whose JSON body is refused (422, `json_repeated_key`) when an object in it
    names a key twice: the routers that take data from cars, the INRIX feed and operators."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        """FastAPI's handler, behind the check of the body's keys."""
        handler = super().get_route_handler()

        takes_body = self.body_field is not None

        async def checked_handler(request: Request) -> Response:
            content_type = request.headers.get("content-type", "")
            if takes_body and content_type.split(";")[0].strip().endswith("json"):
                try:
                    body = await request.body()  # Starlette keeps it for the handler's read
                except ClientDisconnect:
                    # FastAPI's own read answers a body cut off as before (no 500)
                    return await handler(request)
                try:
                    refuse_repeated_keys(body)
                except RepeatedKey as error:
                    raise RequestValidationError(
                        [{"loc": ("body",), "msg": str(error), "type": REPEATED_KEY}]
                    ) from None
            return await handler(request)

        return checked_handler
