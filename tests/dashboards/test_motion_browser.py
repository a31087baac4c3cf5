"""The MOTION page in a real Chromium: a simulated MOTION stretch and the fleet's pings, drawn."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import numpy as np
import pytest
from playwright.sync_api import Page, expect
from sqlalchemy import Engine

from app.motion.importer import import_motion_file
from sim.motion.frame import MotionFrame
from sim.motion.traffic import MOTION_STEP_S, MotionRunConfig, simulate_motion_run
from sim.motion.write import write_motion_json
from tests.dashboards.support import add_users
from tests.dashboards.test_browser import browser, log_in, page, screenshot  # noqa: F401
from tests.support.fleet import drive, post_pings
from tests.support.servers import live_server
from tests.support.tokens import issue

pytestmark = pytest.mark.browser


def simulated_motion(store: Path, tmp_path: Path, start: datetime) -> None:
    """Two minutes of two lanes on the corridor's MOTION section, imported into `store`."""
    config = MotionRunConfig(
        start_unix_s=start.timestamp(),
        duration_s=120.0,
        section_start_m=6500.0,
        section_length_m=1500.0,
        lanes=2,
        seed=5,
    )
    trajectories = simulate_motion_run(config, np.full(int(120 / MOTION_STEP_S), 28.0))
    path = tmp_path / "motion.json"
    write_motion_json(path, trajectories, MotionFrame(), run_id=1)
    assert import_motion_file(path, store).documents > 0


def test_the_motion_page_draws_the_day_with_the_fleet_on_top(
    page: Page,  # noqa: F811
    seeded_database_url: str,
    seeded_engine: Engine,
    tmp_path: Path,
) -> None:
    add_users(seeded_engine)
    now = datetime.now(UTC).replace(microsecond=0)
    start = now - timedelta(seconds=150)
    if (start + timedelta(seconds=130)).date() != start.date():
        # two minutes of MOTION across a UTC midnight are two days, and the page opens on the
        # newer one: run just after midnight (the pings then up to 2 min ahead, which the API
        # accepts within its 300 s)
        start = datetime.combine(now.date(), datetime.min.time(), UTC)
    store = tmp_path / "motion"
    simulated_motion(store, tmp_path, start)
    with (
        live_server(seeded_database_url, planner_enabled=False, motion_dir=store) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        token = issue(seeded_engine, "admin")
        # 60 engaged pings and 40 not: the day's share is 60 %.
        post_pings(
            client,
            token,
            drive(
                "SF-001", start + timedelta(seconds=5), 6600.0, 25.0, 60, controller_engaged=True
            ),
        )
        post_pings(
            client,
            token,
            drive(
                "SF-002", start + timedelta(seconds=10), 6550.0, 24.0, 40, controller_engaged=False
            ),
        )
        log_in(page, base, "viewer", "/analytics/motion")
        day = start.date().isoformat()
        expect(page.get_by_role("link", name=day)).to_have_attribute("aria-current", "page")
        expect(page.locator("#engagement")).to_contain_text(
            "controllers were engaged 60 % of the fleet's pings"
        )
        # the day is said to be UTC's, and the page's units the paper figure's, not the
        # footer every other page has (local time, mph, postmiles)
        expect(page.locator("#engagement")).to_contain_text("(the UTC day")
        expect(page.locator("footer")).to_contain_text(
            "Days are UTC days (the MOTION store’s); the figure’s clock is local, as in the "
            "paper’s figure · speeds in m/s"
        )
        figure = page.locator("#motion-figure")
        expect(figure).to_have_attribute("src", f"/analytics/motion.png?date={day}")
        page.wait_for_function(
            "() => { const img = document.getElementById('motion-figure');"
            " return img.complete && img.naturalWidth >= 1000; }",
            timeout=60_000,
        )
        screenshot(page, "motion.png")
        png = page.request.get(f"{base}/analytics/motion.png?date={day}")
        assert png.headers["content-type"] == "image/png"
        assert png.body()[:8] == b"\x89PNG\r\n\x1a\n"
        missing = page.request.get(f"{base}/analytics/motion.png?date=2001-01-01")
        assert missing.status == 404
        # the last day of the calendar: its window's end overflowed, a 500 (the page); a day
        # no data can have is refused as a bad date
        for path in ("/analytics/motion", "/analytics/motion.png"):
            beyond = page.request.get(f"{base}{path}?date=9999-12-31")
            assert beyond.status == 400, path
            assert "outside 1970-2199" in beyond.text()
