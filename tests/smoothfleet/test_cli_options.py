"""Numeric options refuse NaN and infinity where they come in, not far downstream."""

from __future__ import annotations

import math

import click
import pytest

from smoothfleet.cli.common import FiniteFloatRange


def test_clicks_own_range_lets_nan_through() -> None:
    """Why the project has its own: every comparison with NaN is false, bounds included."""
    assert math.isnan(click.FloatRange(min=1).convert("nan", None, None))


@pytest.mark.parametrize("text", ["nan", "NaN", "inf", "-inf"])
def test_a_non_finite_number_is_refused_by_the_option(text: str) -> None:
    with pytest.raises(click.BadParameter, match="is not a finite number"):
        FiniteFloatRange().convert(text, None, None)
    with pytest.raises(click.BadParameter):
        FiniteFloatRange(min=1).convert(text, None, None)


def test_finite_numbers_keep_the_ranges_bounds() -> None:
    assert FiniteFloatRange(min=0.1).convert("2.5", None, None) == 2.5
    with pytest.raises(click.BadParameter, match=">=0.1"):
        FiniteFloatRange(min=0.1).convert("0.05", None, None)
