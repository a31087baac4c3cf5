"""The dashboard in a real headless Chromium (Debian's /usr/bin/chromium driven by Playwright).

Data arrives the way it does in the field, through the API while the page is open; the tests
watch the page change without reloading it. Screenshots go to tests/artifacts/ (git-ignored).
"""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import httpx
import pytest
from playwright.sync_api import BrowserContext, Page, expect, sync_playwright
from sqlalchemy import Engine, text

from tests.dashboards.support import PASSWORDS, add_users
from tests.dashboards.test_pages import post_fleet_data
from tests.support.fleet import drive, healthy_status, post_pings, post_status
from tests.support.servers import live_server
from tests.support.tokens import issue

pytestmark = pytest.mark.browser

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ARTIFACTS = Path(__file__).resolve().parents[1] / "artifacts"


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[BrowserContext]:
    """Chromium with a fresh profile, never a downloaded browser."""
    if not CHROMIUM.exists():
        pytest.fail("Debian's chromium is missing: apt-get install -y chromium (scripts/test does)")
    profile = tmp_path_factory.mktemp("chromium-profile")
    with sync_playwright() as playwright:
        context = playwright.chromium.launch_persistent_context(
            str(profile),
            executable_path=str(CHROMIUM),
            headless=True,
            args=CHROMIUM_ARGS,
            viewport={"width": 1500, "height": 1000},
        )
        yield context
        context.close()
    shutil.rmtree(profile, ignore_errors=True)


@pytest.fixture
def page(browser: BrowserContext) -> Iterator[Page]:
    browser.clear_cookies()
    page = browser.new_page()
    yield page
    page.close()


def screenshot(page: Page, name: str) -> None:
    ARTIFACTS.mkdir(exist_ok=True)
    page.screenshot(path=str(ARTIFACTS / name), full_page=True)


def log_in(page: Page, base: str, role: str, path: str = "/fleet") -> None:
    page.goto(f"{base}{path}")
    expect(page).to_have_url(f"{base}/login?next={path.replace('/', '%2F')}")
    page.get_by_label("Username").fill(role)
    page.get_by_label("Password").fill(PASSWORDS[role])
    page.get_by_role("button", name="Log in").click()
    expect(page).to_have_url(f"{base}{path}")


def report(client: httpx.Client, token: str, vehicle_id: str) -> None:
    now = datetime.now(UTC).replace(microsecond=0)
    post_pings(
        client,
        token,
        drive(vehicle_id, now - timedelta(seconds=5), 4000.0, 24.0, 5, controller_engaged=True),
    )
    post_status(client, token, vehicle_id, **healthy_status(now))


def test_fleet_page_fills_live_and_a_stale_status_turns_red(
    page: Page, seeded_database_url: str, seeded_engine: Engine
) -> None:
    add_users(seeded_engine)
    # A status is amber from 3 s and red from 6 s here, and the page refreshes every second,
    # so the test sees in seconds what the field sees in a minute.
    with (
        live_server(
            seeded_database_url,
            planner_enabled=False,
            readiness_status_age_s=(3.0, 6.0),
            # the whole test fleet falls silent at once: ages against the wall clock after 1 s
            readiness_server_lag_s=1.0,
            dashboard_refresh_s=1.0,
        ) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        # every request the pages make is answered (assets, live refreshes, the icon)
        failed: list[str] = []
        page.on(
            "response", lambda r: failed.append(f"{r.status} {r.url}") if r.status >= 400 else None
        )
        log_in(page, base, "viewer")
        row = page.locator('tr[data-vehicle="SF-001"]')
        expect(page.locator("tr[data-vehicle]")).to_have_count(100)
        expect(row).to_have_attribute("data-verdict", "not cleared")
        page.evaluate("window.notReloaded = true")

        token = issue(seeded_engine, "admin")
        report(client, token, "SF-001")
        report(client, token, "SF-002")

        expect(row).to_have_attribute("data-verdict", "cleared", timeout=10_000)
        expect(page.locator('[data-count="cleared"]')).to_have_text("2")
        gps = row.locator('[data-check="gps"]')
        expect(gps).to_have_attribute("data-level", "green")
        expect(gps).to_have_attribute(
            "title", "GPS: fix, 11 sat (amber at 6 satellites or fewer, red at 4)"
        )
        assert page.evaluate("window.notReloaded") is True
        screenshot(page, "fleet-live.png")
        assert failed == []

        # The car stops reporting: its status check goes amber, then red, and it loses clearance.
        status = row.locator('[data-check="status"]')
        expect(status).to_have_attribute("data-level", "red", timeout=15_000)
        expect(row).to_have_attribute("data-verdict", "not cleared")
        expect(row.locator('[data-field="reasons"]')).to_contain_text("no status for")
        assert page.evaluate("window.notReloaded") is True
        screenshot(page, "fleet-stale.png")

        # Filters: only the Toyotas, then only the cars with a GPS problem (none).
        page.get_by_label("Make").select_option("Toyota")
        expect(page).to_have_url(f"{base}/fleet?route=&make=Toyota&problem=")
        makes = page.locator("tr[data-vehicle] td:nth-child(2)").all_inner_texts()
        assert makes
        assert all(make.startswith("Toyota") for make in makes)


def test_an_operators_morning(
    page: Page, browser: BrowserContext, seeded_database_url: str, seeded_engine: Engine
) -> None:
    """Which cars can go out, and if not, why: filter, read the reason, fix the car, and watch
    the fleet page (open in another tab) follow without a reload."""
    add_users(seeded_engine)
    with (
        live_server(seeded_database_url, planner_enabled=False, dashboard_refresh_s=1.0) as base,
        httpx.Client(base_url=base, timeout=30) as client,
    ):
        token = issue(seeded_engine, "admin")
        now = datetime.now(UTC).replace(microsecond=0)
        for vehicle_id in ("SF-001", "SF-002"):
            report(client, token, vehicle_id)
        post_pings(client, token, drive("SF-003", now - timedelta(seconds=5), 4000.0, 24.0, 5))
        post_status(client, token, "SF-003", **healthy_status(now, acc_available=False))

        log_in(page, base, "operator")
        page.get_by_label("Problem").select_option("not-cleared")
        expect(page).to_have_url(f"{base}/fleet?route=&make=&problem=not-cleared")
        rows = page.locator("tr[data-vehicle]")
        expect(rows).to_have_count(98)
        expect(page.locator('[data-reason="acc"]')).to_have_text("ACC 1")
        row = page.locator('tr[data-vehicle="SF-003"]')
        expect(row.locator('[data-field="reasons"]')).to_have_text("ACC not available")
        for width in (1400, 1024):
            page.set_viewport_size({"width": width, "height": 900})
            right = row.locator('[data-field="reasons"]').evaluate(
                "cell => cell.getBoundingClientRect().right"
            )
            assert right <= width, f"reasons cut off at {width} px"
            screenshot(page, f"morning-not-cleared-{width}.png")

        fleet_tab = browser.new_page()
        fleet_tab.set_viewport_size({"width": 1024, "height": 900})
        fleet_tab.goto(f"{base}/fleet")
        watched = fleet_tab.locator('tr[data-vehicle="SF-003"]')
        expect(watched).to_have_attribute("data-verdict", "not cleared")
        fleet_tab.evaluate("window.notReloaded = true")
        map_tab = browser.new_page()
        map_tab.set_viewport_size({"width": 1400, "height": 900})
        map_tab.goto(f"{base}/map")
        marker = map_tab.locator('svg[data-chart="corridor-map"] a[data-vehicle="SF-003"]')
        expect(marker).to_have_attribute("data-state", "not engaged")
        expect(map_tab.locator('[data-state-count="engaged"]')).to_have_text("2")
        map_tab.evaluate("window.notReloaded = true")

        row.get_by_role("link", name="SF-003").click()
        expect(page).to_have_url(f"{base}/vehicles/SF-003")
        expect(page.locator("ul.problems")).to_have_text("ACC not available")
        page.get_by_label("In maintenance").check()
        page.get_by_label("Note").fill("ACC fault: dealer Tuesday")
        page.get_by_role("button", name="Save maintenance").click()
        expect(page.get_by_role("status")).to_have_text("Maintenance saved.")
        page.locator('form.assignment select[name="controller"]').select_option("simple")
        page.get_by_role("button", name="Save assignment").click()
        expect(page.get_by_role("status")).to_have_text("Assignment saved.")

        expect(watched).to_have_attribute("data-verdict", "maintenance", timeout=10_000)
        expect(watched.locator('[data-field="reasons"]')).to_have_text(
            "in maintenance: ACC fault: dealer Tuesday"
        )
        expect(watched.locator('[data-field="controller"]')).to_have_text("simple")
        assert fleet_tab.evaluate("window.notReloaded") is True
        screenshot(fleet_tab, "morning-fleet-after-1024.png")
        fleet_tab.set_viewport_size({"width": 1400, "height": 900})
        screenshot(fleet_tab, "morning-fleet-after-1400.png")
        fleet_tab.close()

        # The mechanics fixed it on the spot: SF-003 drives with its controller engaged.
        later = datetime.now(UTC).replace(microsecond=0)
        post_pings(
            client,
            token,
            drive("SF-003", later - timedelta(seconds=3), 6000.0, 24.0, 3, controller_engaged=True),
        )
        expect(marker).to_have_attribute("data-state", "engaged", timeout=10_000)
        expect(map_tab.locator('[data-state-count="engaged"]')).to_have_text("3")
        assert map_tab.evaluate("window.notReloaded") is True
        screenshot(map_tab, "morning-map-1400.png")
        map_tab.set_viewport_size({"width": 1024, "height": 900})
        screenshot(map_tab, "morning-map-1024.png")
        marker.click()
        expect(map_tab).to_have_url(f"{base}/vehicles/SF-003")
        map_tab.close()


def test_an_operator_changes_an_assignment(
    page: Page, seeded_database_url: str, seeded_engine: Engine
) -> None:
    add_users(seeded_engine)
    with live_server(seeded_database_url, planner_enabled=False) as base:
        log_in(page, base, "operator", "/vehicles/SF-003")
        page.get_by_label("Lane").select_option("4")
        page.get_by_label("Route").fill("B")
        page.locator('form.assignment select[name="controller"]').select_option("simple")
        page.get_by_role("button", name="Save assignment").click()

        expect(page.get_by_role("status")).to_have_text("Assignment saved.")
        expect(page.locator('[data-field="lane"]')).to_have_text("4")
        expect(page.locator('[data-field="route"]')).to_have_text("B")
        screenshot(page, "vehicle-assignment.png")
    with seeded_engine.connect() as connection:
        row = connection.execute(
            text(
                "SELECT assigned_lane, route, controller_name FROM dim_vehicle "
                "WHERE vehicle_id = 'SF-003'"
            )
        ).one()
    assert tuple(row) == (4, "B", "simple")


def test_a_viewer_sees_no_change_forms_and_unknown_vehicles_are_404(
    page: Page, seeded_database_url: str, seeded_engine: Engine
) -> None:
    add_users(seeded_engine)
    with live_server(seeded_database_url, planner_enabled=False) as base:
        log_in(page, base, "viewer", "/vehicles/SF-003")
        expect(page.get_by_role("button", name="Save assignment")).to_have_count(0)
        expect(page.get_by_text("Your role is viewer")).to_be_visible()
        response = page.goto(f"{base}/vehicles/NOPE-1")
        assert response is not None
        assert response.status == 404
        expect(page.get_by_role("heading", name="Unknown vehicle")).to_be_visible()


def test_plan_page_shows_the_published_plan_as_charts(
    page: Page, seeded_database_url: str, seeded_engine: Engine
) -> None:
    add_users(seeded_engine)
    with live_server(seeded_database_url, planner_enabled=False) as base:
        post_fleet_data(base, seeded_engine)
        log_in(page, base, "viewer", "/plans")

        lane_chart = page.locator('img[data-chart="plan-lane-1"]')
        expect(lane_chart).to_be_visible()
        expect(lane_chart).to_have_attribute("alt", "Target speed of lane 1 along the corridor")
        heat = page.locator('img[data-chart="plan-heatmap"]')
        expect(heat).to_be_visible()
        assert heat.evaluate("image => image.naturalWidth") > 400  # the PNG decoded
        box = lane_chart.bounding_box()
        assert box is not None
        assert box["width"] > 400
        assert box["height"] > 100
        screenshot(page, "plans.png")

        page.goto(f"{base}/vehicles/SF-001")
        expect(page.locator('img[data-chart="vehicle-speed"]')).to_be_visible()
        screenshot(page, "vehicle.png")
        page.goto(f"{base}/analytics")
        expect(page.locator('img[data-chart="engagement-share"]')).to_be_visible()
        expect(page.locator('img[data-chart="edie-fuel"]')).to_be_visible()
        screenshot(page, "analytics.png")
        page.goto(f"{base}/feeds")
        expect(page.locator('img[data-chart="inrix-latency"]')).to_be_visible()
        screenshot(page, "feeds.png")
