"""The API's error shape (docs/interfaces.md): every error body, as the server sends it and the
agent reads it."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class FieldError(BaseModel):
    """One rejected field of a request (FastAPI's validation error item)."""

    model_config = ConfigDict(extra="allow")

    loc: list[str | int]
    msg: str
    type: str


class ErrorResponse(BaseModel):
    """The body of every error: a sentence, or for a malformed request the list of its fields."""

    detail: str | list[FieldError]
