"""Load the project's seed data (corridor, segments, roster) idempotently.

Dimensions are upserted (seed files may be corrected); vehicles that already exist are left as
they are, so an operator's assignment changes survive a re-seed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.orm import Session

from app.models import Corridor, I24Segment, InrixSegment, Vehicle
from app.vehicles.service import parse_roster_csv, upsert_vehicles

CORRIDOR_COLUMNS = (
    "corridor_id",
    "name",
    "direction",
    "lanes",
    "length_m",
    "speed_limit_mps",
    "min_target_speed_mps",
    "postmile_at_start",
)


@dataclass(frozen=True)
class SeedCounts:
    """Rows present after seeding."""

    corridors: int
    inrix_segments: int
    i24_segments: int
    vehicles: int


def seed_corridor_document() -> dict[str, Any]:
    """The packaged corridor file (built by `python -m seed_data.build`)."""
    text = resources.files("seed_data").joinpath("i24_wb_corridor.json").read_text()
    document: dict[str, Any] = json.loads(text)
    return document


def _upsert(session: Session, model: type[Any], rows: list[dict[str, Any]], key: str) -> None:
    statement = insert(model).values(rows)
    updates = {name: statement.excluded[name] for name in rows[0] if name != key}
    session.execute(statement.on_conflict_do_update(index_elements=[key], set_=updates))


def seed(session: Session) -> SeedCounts:
    """Upsert the seed corridor and its segments, add the seed roster's missing vehicles."""
    document = seed_corridor_document()
    corridor = {name: document["corridor"][name] for name in CORRIDOR_COLUMNS}
    _upsert(session, Corridor, [corridor], "corridor_id")
    inrix = [{**row, "corridor_id": corridor["corridor_id"]} for row in document["inrix_segments"]]
    _upsert(session, InrixSegment, inrix, "xd_code")
    subs = [{**row, "corridor_id": corridor["corridor_id"]} for row in document["i24_segments"]]
    _upsert(session, I24Segment, subs, "i24_segment_id")
    with resources.as_file(resources.files("seed_data").joinpath("roster.csv")) as roster:
        upsert_vehicles(session, parse_roster_csv(roster), update_existing=False, label="seed")
    session.flush()

    def count(model: type[Any]) -> int:
        return int(session.scalar(select(func.count()).select_from(model)) or 0)

    return SeedCounts(count(Corridor), count(InrixSegment), count(I24Segment), count(Vehicle))
