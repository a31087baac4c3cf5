"""The date-cluster bootstrap, against draws worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from sim.date_resampling import date_resampled_means


def test_one_date_always_gives_its_own_mean() -> None:
    means = date_resampled_means([[1.0, 2.0, 6.0]], resamples=50)
    assert means.shape == (50,)
    assert np.all(means == 3.0)


def test_two_dates_give_the_three_pooled_means_in_the_binomial_proportions() -> None:
    # dates A = [1, 1] and B = [3]: AA pools [1, 1, 1, 1] -> 1, AB and BA pool [1, 1, 3] ->
    # 5/3, BB pools [3, 3] -> 3; drawn with chances 1/4, 1/2, 1/4
    means = date_resampled_means([[1.0, 1.0], [3.0]], resamples=20_000, seed=3)
    values, counts = np.unique(np.round(means, 12), return_counts=True)
    assert values == pytest.approx([1.0, 5.0 / 3.0, 3.0])
    assert counts / len(means) == pytest.approx([0.25, 0.5, 0.25], abs=0.015)


def test_the_same_seed_draws_the_same_dates() -> None:
    by_date = [[0.5, 1.5], [2.0], [4.0, -1.0, 0.0]]
    assert np.array_equal(date_resampled_means(by_date), date_resampled_means(by_date))
    assert not np.array_equal(date_resampled_means(by_date), date_resampled_means(by_date, seed=1))


@pytest.mark.parametrize("by_date", [[], [[1.0], []]])
def test_a_date_without_drives_is_refused(by_date: list[list[float]]) -> None:
    with pytest.raises(ValueError, match="at least one drive"):
        date_resampled_means(by_date)


def test_no_resample_is_refused() -> None:
    with pytest.raises(ValueError, match="resamples must be at least 1"):
        date_resampled_means([[1.0]], resamples=0)
