"""Cross-validation folds that keep whole dates apart.

Two drives of one date share its traffic (the same waves, often the same minutes), so a
controller tuned on one and scored on the other is scored on what it was tuned on. A fold holds
out every drive of its dates; the date is the first 10 characters of a drive's name
(`2021-03-08-22-35-14_masterArray_0_5373` -> `2021-03-08`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sim.drives import Drive

DATE_CHARS = 10


def drive_date(drive: Drive) -> str:
    """The date a drive was recorded on (YYYY-MM-DD, the start of its name)."""
    return drive.name[:DATE_CHARS]


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


def date_folds(drives: Sequence[Drive], folds: int) -> list[Fold]:
    """`folds` splits: the sorted dates dealt round-robin, each fold holding out its share."""
    dates = sorted({drive_date(drive) for drive in drives})
    if folds < 2:
        raise ValueError(f"cross-validation needs at least 2 folds, got {folds}")
    if len(dates) < folds:
        raise ValueError(f"{len(dates)} dates cannot fill {folds} folds")
    result = []
    for index in range(folds):
        held = set(dates[index::folds])
        result.append(
            Fold(
                index,
                tuple(drive for drive in drives if drive_date(drive) not in held),
                tuple(drive for drive in drives if drive_date(drive) in held),
            )
        )
    return result
