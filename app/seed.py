"""Load the project's seed data (corridor, segments, roster) idempotently.

Dimensions are upserted (seed files may be corrected); vehicles that already exist are left as
they are, so an operator's assignment changes survive a re-seed. The policies the agent package
ships for the RL controllers the roster runs are stored first: its rows name them by sha256.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.dialects.postgresql import insert
from sqlalchemy.orm import Session

from app.models import Corridor, I24Segment, InrixSegment, Vehicle
from app.policies.service import ManifestConflict, store_shipped_policy
from app.vehicles.schemas import RosterRow
from app.vehicles.service import parse_roster_csv, upsert_vehicles
from contract.controllers import RL_CONTROLLERS

log = logging.getLogger(__name__)

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
    # controller -> sha256 of the shipped policy each RL controller of the roster runs (held by
    # the server, for the cars to download)
    policies: dict[str, str]


def seed_corridor_document() -> dict[str, Any]:
    """The packaged corridor file (built by `python -m seed_data.build`)."""
    text = resources.files("seed_data").joinpath("i24_wb_corridor.json").read_text()
    document: dict[str, Any] = json.loads(text)
    return document


def _upsert(session: Session, model: type[Any], rows: list[dict[str, Any]], key: str) -> None:
    statement = insert(model).values(rows)
    updates = {name: statement.excluded[name] for name in rows[0] if name != key}
    session.execute(statement.on_conflict_do_update(index_elements=[key], set_=updates))


def _store_shipped_policies(session: Session, rows: Sequence[RosterRow]) -> dict[str, str]:
    """Store the shipped policy of each RL controller the roster runs: a row may name a policy
    only when the server holds it (the car downloads it from here by that sha256). Returns
    controller -> the sha256 the roster's rows name."""
    stored: dict[str, str] = {}
    for controller in sorted({row.controller_name for row in rows} & RL_CONTROLLERS.keys()):
        try:
            store_shipped_policy(session, controller, "seed")
        except ManifestConflict as conflict:
            # The bytes the rows name are held, which is all the roster and its cars need; a
            # stored policy's manifest never changes, so the one it was first stored with stands.
            log.warning("seed: %s; it is kept as stored", conflict)
        stored[controller] = next(
            str(row.controller_params["policy_sha256"])
            for row in rows
            if row.controller_name == controller
        )
    return stored


def seed(session: Session) -> SeedCounts:
    """Upsert the seed corridor and its segments, store the policies the seed roster names, add
    the roster's missing vehicles."""
    document = seed_corridor_document()
    corridor = {name: document["corridor"][name] for name in CORRIDOR_COLUMNS}
    _upsert(session, Corridor, [corridor], "corridor_id")
    inrix = [{**row, "corridor_id": corridor["corridor_id"]} for row in document["inrix_segments"]]
    _upsert(session, InrixSegment, inrix, "xd_code")
    subs = [{**row, "corridor_id": corridor["corridor_id"]} for row in document["i24_segments"]]
    _upsert(session, I24Segment, subs, "i24_segment_id")
    with resources.as_file(resources.files("seed_data").joinpath("roster.csv")) as roster:
        rows = parse_roster_csv(roster)
    policies = _store_shipped_policies(session, rows)
    upsert_vehicles(session, rows, update_existing=False, label="seed")
    session.flush()

    def count(model: type[Any]) -> int:
        return int(session.scalar(select(func.count()).select_from(model)) or 0)

    return SeedCounts(
        count(Corridor), count(InrixSegment), count(I24Segment), count(Vehicle), policies
    )
