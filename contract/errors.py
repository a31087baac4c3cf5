"""The API's error shape (docs/interfaces.md): every error body, as the server sends it and the
agent reads it.

A 503 carries a machine-readable `code` telling a car what it means for its plan:
- `no_valid_plan`: the server holds no valid plan for the car's corridor and lane; the car drops
  the plan it follows and leaves the car to its stock ACC (paper: "hand back");
- `database_unavailable`: the server cannot reach its database (or it does not answer in time);
  the car keeps following the plan it holds until that plan's `valid_until`, and retries.
A 503 without a code is read as `database_unavailable`: only an explicit "no valid plan" ends a
plan early.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict

ErrorCode = Literal["no_valid_plan", "database_unavailable"]
NO_VALID_PLAN: ErrorCode = "no_valid_plan"
DATABASE_UNAVAILABLE: ErrorCode = "database_unavailable"


class FieldError(BaseModel):
    """One rejected field of a request (FastAPI's validation error item)."""

    model_config = ConfigDict(extra="allow")

    loc: list[str | int]
    msg: str
    type: str


class ErrorResponse(BaseModel):
    """The body of every error: a sentence, or for a malformed request the list of its fields."""

    detail: str | list[FieldError]
    code: ErrorCode | None = None
