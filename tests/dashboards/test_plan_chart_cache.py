"""The plans page keeps the lane charts of the plans it drew last: a plan never changes, so
each needs drawing once, and the cache stays bounded however many plans are opened."""

from __future__ import annotations

import pytest
from markupsafe import Markup

from dashboards.pages.plans import LaneChartCache


def charts_of(plan_id: int) -> list[tuple[int, Markup]]:
    return [(lane, Markup(f'<img data-chart="plan-{plan_id}-lane-{lane}">')) for lane in (1, 2)]


def test_a_plan_drawn_once_is_served_again() -> None:
    cache = LaneChartCache(kept=2)
    assert cache.get(7) is None
    cache.put(7, charts_of(7))
    assert cache.get(7) == charts_of(7)


def test_the_least_recently_used_plan_is_forgotten_beyond_the_bound() -> None:
    cache = LaneChartCache(kept=2)
    cache.put(1, charts_of(1))
    cache.put(2, charts_of(2))
    assert cache.get(1) is not None  # plan 1 looked at again: plan 2 is now the oldest used
    cache.put(3, charts_of(3))
    assert cache.get(2) is None
    assert cache.get(1) == charts_of(1)
    assert cache.get(3) == charts_of(3)


def test_a_cache_keeps_at_least_one_plan() -> None:
    with pytest.raises(ValueError, match="at least one plan"):
        LaneChartCache(kept=0)
