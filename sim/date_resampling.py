"""How far a mean over drives could move with other dates: resampling whole dates.

Drives of one date share its traffic, so they are not independent draws; the unit of chance is
the date, as it is in cross-validation (`sim.folds`). A date-cluster bootstrap draws as many
dates as there are, with replacement, pools every drive of the dates drawn and takes the mean.
The spread of those means says what other dates of the same kind could have shown. Pure numpy;
the docs' intervals (docs/simulation.md, "How large that margin is" and the held-out results)
are printed by scripts that call it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]


def date_resampled_means(
    by_date: Sequence[Sequence[float]], *, resamples: int = 10_000, seed: int = 0
) -> FloatArray:
    """The mean over drives of `resamples` draws of the dates with replacement: `by_date` holds
    each date's drive values (a date weighs as many drives as it has, as in the plain mean)."""
    if resamples < 1:
        raise ValueError(f"resamples must be at least 1, got {resamples}")
    dates = [np.asarray(values, dtype=np.float64) for values in by_date]
    if not dates or any(values.size == 0 for values in dates):
        raise ValueError("every date needs at least one drive, and there must be a date")
    rng = np.random.default_rng(seed)
    return np.array(
        [
            np.concatenate([dates[i] for i in rng.choice(len(dates), len(dates))]).mean()
            for _ in range(resamples)
        ]
    )
