"""Numeric options refuse NaN and infinity where they come in, not far downstream."""

from __future__ import annotations

import math
import re

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


@pytest.mark.parametrize(
    ("server", "says"),
    [
        ("notaurl", "'notaurl': must be an http:// or https:// URL with a host"),
        ("ftp://api:8000", "'ftp://api:8000': must be an http:// or https:// URL with a host"),
        ("http://127.0.0.1:9", "no smoothfleet API answers at http://127.0.0.1:9"),
    ],
)
def test_sim_fleet_names_a_server_it_cannot_use_before_any_car_starts(
    server: str, says: str
) -> None:
    """It started the workers, retried for about 20 s and said only that a worker exited."""
    from smoothfleet.cli.sim.fleet import check_server

    with pytest.raises(click.BadParameter, match=re.escape(says)):
        check_server(server)
