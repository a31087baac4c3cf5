"""A plan's provenance on its page, written for people: times in the page's zone, ages, dashes."""

from __future__ import annotations

from zoneinfo import ZoneInfo

from dashboards.pages.plans import readable_input

CENTRAL = ZoneInfo("America/Chicago")


def test_times_are_in_the_pages_zone_and_nothing_is_a_dash() -> None:
    """The rows under the plan read '2026-12-04T20:33:22.772311+00:00' beside rows in CST, and
    a skipped plan's 'inrix age s None'."""
    assert readable_input("inrix_as_of", "2026-12-04T20:33:22.772311+00:00", CENTRAL) == (
        "inrix_as_of",
        "2026-12-04 14:33:22 CST",
    )
    assert readable_input("inrix_age_s", None, CENTRAL) == ("inrix_age", "—")
    assert readable_input("inrix_as_of", None, CENTRAL) == ("inrix_as_of", "—")
    assert readable_input("inrix_age_s", 236.936, CENTRAL)[0] == "inrix_age"
    window = {"start": "2026-12-04T20:32:00+00:00", "pings": 12}
    assert readable_input("ping_window", window, CENTRAL) == (
        "ping_window",
        "start 2026-12-04 14:32:00 CST, pings 12",
    )
    # text that is no time stays as it is
    assert readable_input("algorithm", "kernel_smooth", CENTRAL) == ("algorithm", "kernel_smooth")
