"""Cross-validation folds that keep whole dates apart.

Two drives of one date share its traffic (the same waves, often the same minutes), so a
controller tuned on one and scored on the other is scored on what it was tuned on. A fold holds
out every drive of its dates (`drive_date`): the date its name begins with, the recordings'
convention (`2021-03-08-22-35-14_masterArray_0_5373` -> `2021-03-08`), or else the date on I-24
of its first sample, so that a drive named otherwise is still put with its own day's traffic.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime
from zoneinfo import ZoneInfo

from sim.drives import Drive

# A name that begins with a calendar date: the recordings' session stamp (UTC, YYYY-MM-DD-...).
DATED_NAME = re.compile(r"(\d{4}-\d{2}-\d{2})(?!\d)")
# I-24's local time: the traffic day a drive belongs to. The shared recordings' sessions start
# in the afternoon or morning there, so their names' dates are their first samples' local dates
# (a drive of the 2021-03-08 evening session starts after midnight UTC, still 03-08 on I-24).
CORRIDOR_TIMEZONE = ZoneInfo("America/Chicago")


def drive_date(drive: Drive) -> str:
    """The date a drive was recorded on (YYYY-MM-DD): the start of its name when that is a
    date, else the local date on I-24 of its first sample."""
    named = DATED_NAME.match(drive.name)
    if named is not None:
        try:
            return datetime.strptime(named.group(1), "%Y-%m-%d").date().isoformat()
        except ValueError:
            pass  # digits in a date's shape that are no date (2021-13-45): use the samples
    return datetime.fromtimestamp(drive.start_unix_s, CORRIDOR_TIMEZONE).date().isoformat()


@dataclass(frozen=True)
class Fold:
    """One split: train on `train`, score on `held_out`; no date is on both sides."""

    index: int
    train: tuple[Drive, ...]
    held_out: tuple[Drive, ...]

    @property
    def train_dates(self) -> list[str]:
        """Dates trained on, sorted."""
        return sorted({drive_date(drive) for drive in self.train})

    @property
    def held_out_dates(self) -> list[str]:
        """Dates held out, sorted."""
        return sorted({drive_date(drive) for drive in self.held_out})


def held_out_dates(dates: Iterable[str], folds: int) -> list[frozenset[str]]:
    """The dates each of `folds` folds holds out: the sorted distinct dates dealt round-robin,
    so every date is held out by exactly one fold and every fold holds out at least one."""
    distinct = sorted(set(dates))
    if folds < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {folds}")
    if len(distinct) < folds:
        raise ValueError(
            f"the drives span {len(distinct)} date{'s' if len(distinct) != 1 else ''} "
            f"({', '.join(distinct)}), and {folds} folds need {folds}, one held out by each: "
            "a date's drives saw the same traffic, so they never sit on both sides"
        )
    return [frozenset(distinct[index::folds]) for index in range(folds)]


def date_folds(drives: Sequence[Drive], folds: int) -> list[Fold]:
    """`folds` splits of the drives, each fold holding out the drives of its dates
    (`held_out_dates`)."""
    return [
        Fold(
            index,
            tuple(drive for drive in drives if drive_date(drive) not in held),
            tuple(drive for drive in drives if drive_date(drive) in held),
        )
        for index, held in enumerate(held_out_dates((drive_date(drive) for drive in drives), folds))
    ]
