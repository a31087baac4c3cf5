"""Restarts: train one policy from several seeds and keep one, chosen on its training drives.

Under the environment of today (limiter, top speed, cut-ins), policies trained from the same
command and different seeds spread widely in how far they drop back: in the gate of
docs/simulation.md ("How much of a retrain's gate is its seed's") four seeds lost 23-298 m on the
recorded-INRIX shockwave drives with one AV. A single seed is then one draw of that spread. The
remedy used across RL is to train several restarts and keep one by a rule that reads only data
the policy may see. Here each restart is scored on the drives it trained on (one AV, cut-ins as in
training, simulated INRIX), and the rule keeps the restart that drops back least:

1. a restart with a collision on its training drives is kept only if every restart has one
   (then the one with the fewest);
2. among the rest, the fewest takeovers (hand-backs to the driver, `DriveScore.takeovers`; since
   2026-12-05, when the scores gained the hand-back `sim evaluate` has: before, none was seen);
3. among the rest, the smallest mean distance lost (`DriveScore.distance_lost_m`), which is what
   the retrains gave away and what the fuel figures do not show;
4. ties: the first seed.

No held-out date is read, so the held-out scores of the kept restart stay held out. A seed is no
property of the policy: the same seed on other drives is another draw, so the choice is made
again for every training (each fold, the final policy) rather than carried from one to another.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from sim.rl.scores import DriveScore


class RestartChoiceError(ValueError):
    """Restarts that cannot be compared (none, or one without a scored drive)."""


@dataclass(frozen=True)
class RestartScores:
    """One restart's seed and its scores on its own training drives."""

    seed: int
    scores: tuple[DriveScore, ...]

    @property
    def collisions(self) -> int:
        """Collisions over its training drives."""
        return sum(score.collisions for score in self.scores)

    @property
    def takeovers(self) -> int:
        """Takeovers over its training drives."""
        return sum(score.takeovers or 0 for score in self.scores)

    @property
    def mean_distance_lost_m(self) -> float:
        """Mean distance lost over its training drives (m)."""
        return math.fsum(score.distance_lost_m for score in self.scores) / len(self.scores)

    def as_dict(self) -> dict[str, Any]:
        """The record a manifest keeps."""
        return {
            "seed": self.seed,
            "collisions": self.collisions,
            "takeovers": self.takeovers,
            "mean_distance_lost_m": self.mean_distance_lost_m,
        }


def choose_restart(restarts: Sequence[RestartScores]) -> int:
    """The index of the restart the rule keeps (see the module docstring)."""
    if not restarts:
        raise RestartChoiceError("no restart to choose from")
    for restart in restarts:
        if not restart.scores:
            raise RestartChoiceError(f"restart of seed {restart.seed} has no scored drive")
        if math.isnan(restart.mean_distance_lost_m):
            raise RestartChoiceError(f"restart of seed {restart.seed} has no distance lost")
        if any(score.takeovers is None for score in restart.scores):
            raise RestartChoiceError(f"restart of seed {restart.seed} was scored with no hand-back")
    return min(
        range(len(restarts)),
        key=lambda index: (
            restarts[index].collisions,
            restarts[index].takeovers,
            restarts[index].mean_distance_lost_m,
            index,
        ),
    )
