"""Values a message may carry only if the warehouse can store them and the domain can mean them.

Pydantic accepts text and numbers PostgreSQL refuses or silently changes: a NUL character (text
cannot hold one), a lone UTF-16 surrogate (not UTF-8 at all), a float beyond a REAL column's
range (stored as infinity), and timestamps no clock could have produced (0001-01-01+05:00 is
1 BC in UTC). Refusing them here, at the edge, names the field in the 422 instead of failing a
whole group commit later.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Annotated
from urllib.parse import urlsplit

from pydantic import (
    AfterValidator,
    AwareDatetime,
    BeforeValidator,
    Field,
    Strict,
    StringConstraints,
    ValidationError,
)

# The JSON Schema side of StorableText, so clients and fuzzers know NUL is not text here.
NO_NUL_PATTERN = "^[^\\u0000]*$"
# A REAL (float4) column: its largest finite value, and a magnitude below which a value is
# stored as 0 (REAL keeps nothing under ~1.4e-45; the margin covers unit conversions at ingest).
FLOAT4_MAX = 3.4028234663852886e38
NEGLIGIBLE = 1e-30
# No message is about a time before the fleet existed or after anyone could plan for.
EARLIEST = datetime(1970, 1, 1, tzinfo=UTC)
LATEST = datetime(2200, 1, 1, tzinfo=UTC)
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
_NUMBERS = (int, float)
_NOT_NUMBERS = (bool, str)
_NOT_TEXT = "timestamp must be ISO 8601 text, e.g. 2026-11-30T12:00:00Z"


def http_url(value: str) -> str:
    """The URL, if it is http(s) and names a host: what the server's and the car's settings
    accept for an address they will call or print."""
    parts = urlsplit(value)
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError("must be an http:// or https:// URL with a host")
    return value


def storable_text(value: str) -> str:
    """The text, if PostgreSQL can store it as given."""
    if "\x00" in value:
        raise ValueError("text must not contain the NUL character (\\u0000)")
    if not value.isascii():
        try:
            value.encode("utf-8")
        except UnicodeEncodeError:
            raise ValueError("text must not contain a lone UTF-16 surrogate") from None
    return value


def real(value: float | None) -> float | None:
    """A finite float as a REAL column keeps it: a magnitude it cannot hold but as 0 is 0.

    PostgreSQL refuses such a value with "underflow" on one path and stores 0 on another (the
    binary COPY); here it is 0 on both.
    """
    if value is None:
        return None
    if not math.isfinite(value) or abs(value) > FLOAT4_MAX:
        raise ValueError("number must be finite and within a REAL's range (about 3.4e38)")
    if value != 0.0 and abs(value) < NEGLIGIBLE:
        return 0.0
    return value


def time_text(value: object) -> object:
    """A timestamp arrives as ISO 8601 text (as documented), never as a number of seconds
    (which pydantic would read as Unix time), neither bare nor quoted."""
    if isinstance(value, str):
        # Text with a colon (every ISO time of day) is no number: most pings end here.
        if ":" not in value and _NUMBER.fullmatch(value.strip()):
            raise ValueError(_NOT_TEXT)
    elif isinstance(value, _NUMBERS) and not isinstance(value, bool):
        raise ValueError(_NOT_TEXT)
    return value


def json_number(value: object) -> object:
    """An integer field takes JSON numbers only: true is not 1, and "25" is not 25, here.

    (Float fields say the same natively with JsonFloat; pydantic's strict int would also refuse
    2.0, which JSON Schema's "integer" allows, so integers keep this check.)
    """
    if isinstance(value, _NOT_NUMBERS):
        raise ValueError("must be a JSON number")
    return value


def plausible_time(value: datetime) -> datetime:
    """A timestamp that exists in UTC and lies between 1970 and 2200."""
    if EARLIEST <= value < LATEST:  # compared as instants, with no conversion to overflow
        return value
    try:
        value.astimezone(UTC)
    except OverflowError:
        raise ValueError("timestamp is outside the calendar once converted to UTC") from None
    raise ValueError("timestamp must lie between 1970 and 2200 (UTC)")


# A float field takes JSON numbers only (true is not 1, "25" is not 25), checked inside
# pydantic-core: ingest validates up to 1,000 pings a request, and a Python validator per field
# cost more than the rest of a ping's validation (bench/ingest.py; docs/performance.md).
JsonFloat = Annotated[float, Strict()]

StorableText = Annotated[
    str, AfterValidator(storable_text), Field(json_schema_extra={"pattern": NO_NUL_PATTERN})
]
# StorableText of at most 64 / 120 characters. The bound sits on the string itself,
# before the NUL check: a Field(max_length=...) on an optional StorableText is applied after
# validation, and its error read "Value should have at most 64 items", not characters.
Text64 = Annotated[
    str,
    StringConstraints(max_length=64),
    AfterValidator(storable_text),
    Field(json_schema_extra={"pattern": NO_NUL_PATTERN}),
]
Text120 = Annotated[
    str,
    StringConstraints(max_length=120),
    AfterValidator(storable_text),
    Field(json_schema_extra={"pattern": NO_NUL_PATTERN}),
]
Timestamp = Annotated[AwareDatetime, BeforeValidator(time_text), AfterValidator(plausible_time)]


@dataclass(frozen=True)
class Problem:
    """The first thing a validation found wrong: where (the location's parts) and what."""

    location: tuple[str, ...]
    message: str

    @property
    def where(self) -> str:
        """The location as `a.b.0`."""
        return ".".join(self.location)

    def __str__(self) -> str:
        return f"{self.where}: {self.message}" if self.location else self.message


def first_problem(error: ValidationError) -> Problem:
    """The first problem of a validation failure, in the words of the check that failed: a
    validator's ValueError read from the exception itself (pydantic's message wraps it in
    "Value error, "), any other check's message as pydantic words it."""
    detail = error.errors(include_url=False)[0]
    raised = detail.get("ctx", {}).get("error")
    if detail["type"] == "value_error" and isinstance(raised, ValueError):
        message = str(raised)
    else:
        message = str(detail["msg"])
    return Problem(tuple(str(part) for part in detail["loc"]), message)
