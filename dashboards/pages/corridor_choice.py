"""The corridor and lane a page is asked for (map, time-space and plans pages)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated

from fastapi import Query

from app.models import Corridor
from dashboards.auth import PageError

# A lane asked for in a page's address: checked against the corridor by `check_lane`, and
# before any query against the most lanes a corridor may have.
LaneNumber = Annotated[int, Query(ge=1, le=12)]


def chosen_corridor(corridors: Sequence[Corridor], corridor_id: str | None) -> Corridor | None:
    """The corridor named, else the first (None: there are none yet).

    A name the warehouse does not hold is refused: the first corridor's data under a mistyped
    or old link would read as the asked one's.
    """
    corridor = next((c for c in corridors if c.corridor_id == corridor_id), None)
    if corridor is None and corridor_id is not None:
        raise PageError(404, "Unknown corridor", f"There is no corridor {corridor_id}.")
    return corridor or (corridors[0] if corridors else None)


def check_lane(corridor: Corridor, lane: int) -> None:
    """A lane the corridor does not have is refused by name: the lane menu would show its first
    lane while the page drew the asked one, and its next refresh would switch lanes unasked."""
    if lane > corridor.lanes:
        raise PageError(
            422,
            "Unknown lane",
            f"{corridor.corridor_id} has lanes 1 to {corridor.lanes}, not {lane}.",
        )
