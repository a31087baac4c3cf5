"""The INRIX segment-speed response as the provider sends it, and its readings in SI units.

Accepted as is: `result.segmentspeeds[]` each with a `timestamp` and `segments[]` holding
`code`, `type`, `speed`, `average`, `reference` (mph), `travelTimeMinutes`, `score` (30
real-time, 20 mixed, 10 historical), `c-Value` (0-100), `segmentClosed` and `subSegments`
(ignored). Unknown fields are ignored. A set without a timestamp takes the response's
`createdDate`; a timestamp without a zone is UTC (the provider's clock).

Each segment is read on its own, as a batch's pings are: one the model refuses (a value out of
range, no code) or a code read twice at one timestamp is refused with its place and reason, and
the snapshot's other readings are kept. A provider that sends one bad segment must not cost the
planner that minute of the whole corridor. So is each segment set: one with no time to read
(its timestamp unreadable, or missing with the response's `createdDate` missing or unreadable)
or whose `segments` is no list is refused whole (`segment` None), and the other sets are kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, StrictBool, ValidationError, field_validator

from contract.units import MPS_PER_MPH
from contract.values import (
    JsonFloat,
    StorableText,
    json_number,
    plausible_time,
    real,
    storable_text,
    time_text,
)

S_PER_MINUTE = 60.0


class InrixFormatError(ValueError):
    """The document is not an INRIX segment-speed response; the message says where."""


def _as_utc(value: datetime | None) -> datetime | None:
    if value is None:
        return None
    return plausible_time(value.replace(tzinfo=UTC) if value.tzinfo is None else value)


class InrixSegment(BaseModel):
    """One segment's reading (mph, as the provider sends it)."""

    model_config = ConfigDict(extra="ignore", allow_inf_nan=False, populate_by_name=True)

    code: StorableText = Field(min_length=1, max_length=64)
    type: StorableText | None = None
    speed: JsonFloat | None = Field(None, ge=0, le=250)
    average: JsonFloat | None = Field(None, ge=0, le=250)
    reference: JsonFloat | None = Field(None, ge=0, le=250)
    travel_time_minutes: JsonFloat | None = Field(None, alias="travelTimeMinutes", ge=0, le=1e6)
    score: int | None = Field(None, ge=0, le=100)
    c_value: JsonFloat | None = Field(None, alias="c-Value", ge=0, le=100)
    segment_closed: StrictBool = Field(False, alias="segmentClosed")

    _integers = field_validator("score", mode="before")(json_number)
    _real = field_validator("speed", "average", "reference", "travel_time_minutes", "c_value")(real)

    @field_validator("code", mode="before")
    @classmethod
    def _code_as_text(cls, value: object) -> object:
        """An XD code is digits: sent as a JSON integer it names the same segment (a float or
        a boolean does not)."""
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            return str(value)
        return value

    @field_validator("segment_closed", mode="before")
    @classmethod
    def _closed_unless_said(cls, value: object) -> object:
        """`"segmentClosed": null` says no more than an absent flag: open."""
        return False if value is None else value


class InrixSegmentSet(BaseModel):
    """Readings of one provider timestamp."""

    model_config = ConfigDict(extra="ignore")

    timestamp: datetime | None = None
    # Each item is read on its own (InrixSegment): a bad one is refused with its place while the
    # others are stored, so any item is acceptable here.
    segments: list[Any] = Field(
        description="segment readings (schema InrixSegment), each read on its own: one that is "
        "not a valid reading is refused in the answer's `refused`, the others stored"
    )

    _text = field_validator("timestamp", mode="before")(time_text)
    _utc = field_validator("timestamp")(_as_utc)


class InrixResult(BaseModel):
    """The `result` member of a response."""

    model_config = ConfigDict(extra="ignore")

    # Each set is read on its own (InrixSegmentSet), as each segment is.
    segmentspeeds: list[Any] = Field(
        description="segment sets (schema InrixSegmentSet), each read on its own: one with no "
        "readable time (its timestamp, else the response's createdDate) or no list of segments "
        "is refused whole in the answer's `refused` (`segment` null), the others stored"
    )


class _CreatedDate(BaseModel):
    """The response's `createdDate`, read apart: unreadable, it costs only the sets that
    need it (those without a timestamp of their own)."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True)

    created_date: datetime | None = Field(None, alias="createdDate")

    _text = field_validator("created_date", mode="before")(time_text)
    _utc = field_validator("created_date")(_as_utc)


class InrixResponse(BaseModel):
    """A segment-speed response as returned by the provider."""

    model_config = ConfigDict(extra="ignore", populate_by_name=True)

    result: InrixResult
    created_date: Any = Field(
        None,
        alias="createdDate",
        description="when the provider made the response (ISO 8601; no zone: UTC): the time of "
        "every set without a timestamp of its own",
    )


@dataclass(frozen=True, slots=True)
class SegmentReading:
    """One segment's reading in SI units, ready for fact_inrix_estimate."""

    xd_code: str
    measured_at: datetime
    speed_mps: float | None
    average_speed_mps: float | None
    reference_speed_mps: float | None
    travel_time_s: float | None
    score: int | None
    c_value: float | None
    is_closed: bool


@dataclass(frozen=True, slots=True)
class RefusedReading:
    """A segment of the response that is not a reading to store, and why."""

    segment_set: int
    segment: int | None  # None: the whole set
    code: str | None
    error: str


@dataclass(frozen=True, slots=True)
class SnapshotReadings:
    """What a response holds: the readings to store and the segments refused."""

    readings: list[SegmentReading]
    refused: list[RefusedReading]


def _mps(mph: float | None) -> float | None:
    return None if mph is None else mph * MPS_PER_MPH


def _first_error(error: ValidationError) -> str:
    """The first thing pydantic found wrong, as "where: what"."""
    first = error.errors(include_url=False)[0]
    where = ".".join(str(part) for part in first["loc"])
    return f"{where}: {first['msg']}" if where else str(first["msg"])


def parse_response(document: Any) -> InrixResponse:
    """The provider response in `document` (parsed JSON); InrixFormatError if it is not one."""
    try:
        return InrixResponse.model_validate(document)
    except ValidationError as error:
        raise InrixFormatError(
            f"not an INRIX segment-speed response: {_first_error(error)}"
        ) from None


def readings(document: Any) -> SnapshotReadings:
    """The readings of a provider response (parsed JSON) in SI units."""
    return readings_of(parse_response(document))


def _segment(item: Any) -> InrixSegment:
    """One item of `segments[]` as a reading; ValueError saying what is wrong if it is none."""
    try:
        return InrixSegment.model_validate(item)
    except ValidationError as error:
        raise ValueError(_first_error(error)) from None


def _echoable(code: str) -> bool:
    """Whether a refused segment's code can be named in the answer: a lone surrogate has no
    UTF-8, so the answer could not be written (a 500 that lost the whole snapshot); such a
    segment is refused with `code` null, its reason saying what was wrong."""
    try:
        storable_text(code)
    except ValueError:
        return False
    return True


def _created_date(value: Any) -> tuple[datetime | None, str]:
    """The response's createdDate, or None and why there is none to use."""
    if value is None:
        return None, "no timestamp (and no createdDate)"
    try:
        return _CreatedDate.model_validate({"createdDate": value}).created_date, ""
    except ValidationError as error:
        return None, f"no timestamp, and the response's {_first_error(error)}"


def _segment_set(item: Any) -> InrixSegmentSet:
    """One item of `segmentspeeds[]`; ValueError saying what is wrong if it is none."""
    try:
        return InrixSegmentSet.model_validate(item)
    except ValidationError as error:
        raise ValueError(_first_error(error)) from None


def readings_of(response: InrixResponse) -> SnapshotReadings:
    """The response's readings, converted from mph and minutes to SI units, and its segments
    and segment sets refused (not a reading, a code already read at that timestamp; a set with
    no time or no list of segments)."""
    found: list[SegmentReading] = []
    refused: list[RefusedReading] = []
    created_date, no_created_date = _created_date(response.created_date)
    # (instant, code) -> where it was first read, across the whole response: two segment sets
    # may name one instant in two zones, and a second reading of a code there is refused as
    # within one set, not stored as a "duplicate" of the first
    first_of_code: dict[tuple[datetime, str], tuple[int, int]] = {}
    for number, item_set in enumerate(response.result.segmentspeeds):
        try:
            segment_set = _segment_set(item_set)
        except ValueError as error:
            refused.append(RefusedReading(number, None, None, str(error)))
            continue
        measured_at = segment_set.timestamp or created_date
        if measured_at is None:
            refused.append(RefusedReading(number, None, None, no_created_date))
            continue
        for index, item in enumerate(segment_set.segments):
            code = item.get("code") if isinstance(item, dict) else None
            named = code if isinstance(code, str) and _echoable(code) else None
            try:
                segment = _segment(item)
            except ValueError as error:
                refused.append(RefusedReading(number, index, named, str(error)))
                continue
            key = (measured_at, segment.code)
            if key in first_of_code:
                kept_set, kept_index = first_of_code[key]
                where = (
                    f"segment {kept_index}"
                    if kept_set == number
                    else f"segment set {kept_set}, segment {kept_index}"
                )
                refused.append(
                    RefusedReading(
                        number,
                        index,
                        segment.code,
                        f"code {segment.code} already read at this timestamp ({where}, which is "
                        "kept)",
                    )
                )
                continue
            first_of_code[key] = (number, index)
            found.append(
                SegmentReading(
                    xd_code=segment.code,
                    measured_at=measured_at,
                    speed_mps=_mps(segment.speed),
                    average_speed_mps=_mps(segment.average),
                    reference_speed_mps=_mps(segment.reference),
                    travel_time_s=(
                        None
                        if segment.travel_time_minutes is None
                        else segment.travel_time_minutes * S_PER_MINUTE
                    ),
                    score=segment.score,
                    c_value=segment.c_value,
                    is_closed=segment.segment_closed,
                )
            )
    return SnapshotReadings(found, refused)
