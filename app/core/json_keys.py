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

from collections.abc import Callable, Coroutine
from typing import Any

import jiter
from fastapi import Request, Response
from fastapi.exceptions import RequestValidationError
from fastapi.routing import APIRoute


class RepeatedKey(ValueError):
    """An object of the body names a key twice; the message says which and where."""


def refuse_repeated_keys(body: bytes) -> None:
    """RepeatedKey when an object of the JSON `body` names a key twice.

    A body that is not JSON at all passes: the endpoint's own parser reports what is wrong with
    it. The two parses differ in the duplicate check alone, so a body the strict one refuses and
    the lenient one reads repeats a key.
    """
    try:
        jiter.from_json(body, catch_duplicate_keys=True)
    except ValueError as strict:
        try:
            jiter.from_json(body)
        except ValueError:
            return
        raise RepeatedKey(f"{strict}: which value is meant is ambiguous") from None


class RepeatedKeysRefused(APIRoute):
    """A route whose JSON body is refused (422, `json_repeated_key`) when an object in it
    names a key twice: the routers that take data from cars, the INRIX feed and operators."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        """FastAPI's handler, behind the check of the body's keys."""
        handler = super().get_route_handler()

        async def checked_handler(request: Request) -> Response:
            body = await request.body()  # Starlette keeps it for the handler's own read
            if body:
                try:
                    refuse_repeated_keys(body)
                except RepeatedKey as error:
                    raise RequestValidationError(
                        [{"loc": ("body",), "msg": str(error), "type": "json_repeated_key"}]
                    ) from None
            return await handler(request)

        return checked_handler
